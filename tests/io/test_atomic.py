import pytest

from i2ris_calib.io.atomic import atomic_path, write_json


def test_atomic_path_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.csv"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_atomic_path_renames_on_success(tmp_path):
    target = tmp_path / "sub" / "out.csv"
    with atomic_path(target) as tmp:
        assert tmp.suffix == ".csv"
        tmp.write_text("ok")
    assert target.read_text() == "ok"


def test_write_json_nan_is_null(tmp_path):
    import json

    import numpy as np

    write_json(tmp_path / "a.json", {"x": np.float64("nan"), "y": np.arange(2)})
    assert json.loads((tmp_path / "a.json").read_text()) == {"x": None, "y": [0, 1]}
