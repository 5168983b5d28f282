"""Configuration of the fitting stage (TOML section ``[fit]``, see docs/fit.md)."""

from __future__ import annotations

from dataclasses import dataclass

from i2ris_calib._validate import validated_config

_METHODS = ("lm", "trf")


@dataclass(frozen=True)
class FitConfig:
    """Settings of the fitting stage. Units are in the field names.

    Attributes
    ----------
    method : str
        ``"lm"`` (unbounded Levenberg-Marquardt, as the paper) or ``"trf"`` (bounded).
    n_starts : int
        Data-driven starts per EGPI fit (the first is the plain data-driven one); 0
        (default): by the data's size (:func:`i2ris_calib.fitting.pipeline.search_starts`:
        8 up to 5,000 fitted samples, fewer on longer recordings, at least 2).
    n_starts_gpi : int
        Starts per fit of the other kinds (GPI, two-tendon, coupled, Bouc-Wen); 0: as
        ``n_starts``.
    max_restarts : int
        Most restarts from perturbations of the best end (basin hopping) while fewer
        than two starts reached the best cost (docs/fit.md, "the global search"); 0:
        a local search (only the best screened start polished, no restarts).
    seed : int
        Seed of the start variations.
    max_nfev : int
        LM iterations allowed per LM call of the final run (then flagged not
        converged); finite-difference Jacobian evaluations are not counted.
    n_operators : int
        n, the number of non-zero thresholds (n + 1 play operators, Eq14).
    deadband_counts : float
        Dead band of ``v'`` (input unit, counts for an encoder) for the EGPI output
        switch; negative (default) = derived from the input: max(3 x input noise sd,
        0.03 % of the input range), 1.8 counts over a 6000-count range. Small: a wide
        band delays the switch back to loading at the turning points.
    fixed_gpi, fixed_egpi : tuple of str
        Parameters held at their start value. ``lam`` by default: lam and the
        envelope scale are exactly redundant (docs/models.md).
    fit_flag_point : bool
        Fit the EGPI flag point v_f (profile search) instead of keeping the
        data-driven estimate.
    holdout_fraction : float
        Fraction of loading cycles held out for validation (0 = none).
    zero_band_counts : float
        |input| at or below this (input unit) is "at rest near zero": such samples
        belong to the direction of the excursion before them (no sample is dropped).
        Negative (default) = derived from the input: max(3 x input noise sd, 0.5 % of
        max |input|).
    min_block_samples : int
        A motion direction with fewer samples outside the zero band is not a dataset.
    signed : bool
        Fit one model per axis on the whole signed input (dataset ``"<axis>±"``)
        instead of one per motion direction: for actuators whose loops cross zero.
        Neither ``signed`` nor ``split``: ``fit`` chooses from the recording
        (docs/fit.md, "Which model").
    split : bool
        Fit the paper's per-direction split even when the recording calls for the
        signed model (``fit --split``).
    loss : str
        ``"linear"`` (Eq24, plain least squares), or the robust ``"soft_l1"`` /
        ``"huber"`` (need ``method = "trf"``) against tracking outliers.
    f_scale_deg : float
        Residual scale (deg) beyond which a robust loss down-weights.
    """

    method: str = "lm"
    n_starts: int = 0
    n_starts_gpi: int = 0
    max_restarts: int = 4
    seed: int = 0
    max_nfev: int = 300
    n_operators: int = 30
    deadband_counts: float = -1.0
    fixed_gpi: tuple[str, ...] = ("lam",)
    fixed_egpi: tuple[str, ...] = ("lam",)
    fit_flag_point: bool = True
    holdout_fraction: float = 0.25
    zero_band_counts: float = -1.0
    min_block_samples: int = 50
    signed: bool = False
    split: bool = False
    loss: str = "linear"
    f_scale_deg: float = 0.5

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
        if self.method not in _METHODS:
            raise ValueError(f"method '{self.method}' is not one of {', '.join(_METHODS)}")
        if self.n_starts < 0 or self.n_starts_gpi < 0:
            raise ValueError("n_starts and n_starts_gpi must be >= 1, or 0 for the data's size")
        if self.max_restarts < 0:
            raise ValueError("max_restarts must be >= 0")
        if self.max_nfev < 10:
            raise ValueError("max_nfev must be >= 10")
        if self.n_operators < 1:
            raise ValueError("n_operators must be >= 1")
        if not 0.0 <= self.holdout_fraction < 1.0:
            raise ValueError("holdout_fraction must be in [0, 1)")
        if self.loss not in ("linear", "soft_l1", "huber"):
            raise ValueError(f"loss '{self.loss}' is not one of linear, soft_l1, huber")
        if self.loss != "linear" and self.method != "trf":
            raise ValueError(f"loss '{self.loss}' needs method = \"trf\"")
        if self.f_scale_deg <= 0:
            raise ValueError("f_scale_deg must be > 0")
        if self.signed and self.split:
            raise ValueError("signed and split exclude each other (neither: chosen from the data)")
        if self.min_block_samples < 1:
            raise ValueError("min_block_samples must be >= 1")
        known_gpi = {"a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn"}
        known_egpi = known_gpi | {"a5", "a6", "kappa", "v_f"}
        for key, names, known in (
            ("fixed_gpi", self.fixed_gpi, known_gpi),
            ("fixed_egpi", self.fixed_egpi, known_egpi),
        ):
            bad = set(names) - known
            if bad:
                raise ValueError(
                    f"{key}: unknown parameter(s) {sorted(bad)}; valid: {', '.join(sorted(known))}"
                )
