"""configs/default.toml stays in step with the config dataclasses."""

from pathlib import Path

from i2ris_calib.config import PipelineConfig
from i2ris_calib.io.config_io import dataclass_from_mapping, load_config, to_toml

ROOT = Path(__file__).resolve().parents[2]


def test_shipped_default_config_equals_code_defaults():
    assert load_config(ROOT / "configs" / "default.toml") == PipelineConfig()


def test_to_toml_round_trips(tmp_path):
    import tomllib

    text = to_toml(PipelineConfig())
    assert dataclass_from_mapping(PipelineConfig, tomllib.loads(text)) == PipelineConfig()


def test_shipped_default_config_lists_every_key():
    """The file is written out in full, so a changed default in the code fails above."""
    import dataclasses

    import tomllib

    doc = tomllib.loads((ROOT / "configs" / "default.toml").read_text())
    for section in dataclasses.fields(PipelineConfig):
        cls = type(getattr(PipelineConfig(), section.name))
        keys = {f.name for f in dataclasses.fields(cls) if f.init}
        written = set(doc.get(section.name, {}))
        # tables of mappings (e.g. [simulate.models]) may be empty and omitted
        assert keys - written <= {"models", "effects"}, (section.name, keys - written)
