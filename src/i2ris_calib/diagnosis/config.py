"""Configuration of the diagnosis stage (TOML section ``[diagnose]``, see docs/diagnosis.md)."""

from __future__ import annotations

from dataclasses import dataclass

from i2ris_calib._validate import validated_config
from i2ris_calib.hysteresis.effects import CATALOGUE


@dataclass(frozen=True)
class DiagnosisConfig:
    """Settings of the diagnosis stage. Units are in the field names.

    Attributes
    ----------
    candidates : tuple of str
        Effects to try (catalogue names); empty = the whole catalogue.
    max_steps : int
        Most effects added.
    alpha : float
        Significance level of the one-sided held-out z-test. The held-out cycles
        are the dataset's (``[fit] holdout_fraction``, the fitting stage's one rule).
    min_rel_improvement : float
        Smallest relative decrease of the held-out RMSE that can name an effect.
    min_delta_bic : float
        Smallest BIC decrease (on the fitted samples) that can name an effect.
    max_samples : int
        Signals are decimated to at most this many samples for the search.
    max_nfev : int
        Cap on least-squares iterations of each candidate's joint refit.
    profile_nfev : int
        Cap on least-squares iterations of the base refit at each grid start.
    restart_nfev : int
        Cap on least-squares iterations of the base refit from a data-driven
        start at the ``n_restarts`` best grid points (input-side effects).
    n_restarts : int
        Grid points (best profiles first) that also get a data-driven base start.
    start_max_nfev : int
        Cap on least-squares iterations when the starting model is polished.
    n_global_starts : int
        Data-driven base starts of the global refit after an effect is named
        (0 = only the candidate's own values).
    global_max_nfev : int
        Evaluation cap of that global refit (its screening runs get a quarter).
    n_finalists : int
        Promising candidates refitted globally (and judged again) before the choice.
    promising_z : float
        Held-out z above which a warm-fitted candidate may become a finalist.
    global_refit_ratio : float
        A finalist whose warm held-out RMSE is more than this multiple of the best
        globally refitted finalist's keeps its warm fit (it is judged, and listed, as
        warm-fitted); ``inf`` refits every finalist.
    choose_by : str
        ``"holdout"`` (lowest held-out RMSE, unless a finalist with a much lower
        BIC is not significantly worse on the held-out cycles) or ``"bic"``
        (lowest BIC) to choose among significant finalists.
    seed : int
        Seed of the random start variations of the global refit.
    """

    candidates: tuple[str, ...] = ()
    max_steps: int = 3
    alpha: float = 0.01
    min_rel_improvement: float = 0.05
    min_delta_bic: float = 10.0
    max_samples: int = 4000
    max_nfev: int = 30
    profile_nfev: int = 4
    restart_nfev: int = 20
    n_restarts: int = 5
    start_max_nfev: int = 60
    n_global_starts: int = 3
    global_max_nfev: int = 400
    n_finalists: int = 3
    promising_z: float = 1.0
    global_refit_ratio: float = 5.0
    choose_by: str = "holdout"
    seed: int = 0

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
        bad = [c for c in self.candidates if c not in CATALOGUE]
        if bad:
            raise ValueError(f"candidates: unknown effect(s) {bad}; valid: {', '.join(CATALOGUE)}")
        if self.max_steps < 0:
            raise ValueError("max_steps must be >= 0")
        if not 0 < self.alpha < 1:
            raise ValueError("alpha must be in (0, 1)")
        if not 0 <= self.min_rel_improvement < 1:
            raise ValueError("min_rel_improvement must be in [0, 1)")
        if self.min_delta_bic < 0:
            raise ValueError("min_delta_bic must be >= 0")
        if self.max_samples < 100:
            raise ValueError("max_samples must be >= 100")
        if self.choose_by not in ("holdout", "bic"):
            raise ValueError("choose_by must be 'holdout' or 'bic'")
        if self.n_restarts < 0:
            raise ValueError("n_restarts must be >= 0")
        if self.n_finalists < 1:
            raise ValueError("n_finalists must be >= 1")
        if self.n_global_starts < 0:
            raise ValueError("n_global_starts must be >= 0")
        if not self.global_refit_ratio > 1:
            raise ValueError("global_refit_ratio must be > 1 (inf: refit every finalist)")
        if (
            min(
                self.max_nfev,
                self.start_max_nfev,
                self.profile_nfev,
                self.restart_nfev,
                self.global_max_nfev,
            )
            < 1
        ):
            raise ValueError("max_nfev, profile_nfev and start_max_nfev must be >= 1")
