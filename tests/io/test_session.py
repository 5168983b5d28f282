"""session.toml loading: clear one-line errors (docs/session.md)."""

from __future__ import annotations

import pytest

from i2ris_calib.errors import CalibError
from i2ris_calib.io.session import load_session

GOOD = """
name = "s"
[marker]
dictionary = "DICT_4X4_50"
marker_size_mm = 0.8
cube_size_mm = 1.0
[cameras.top]
video = "top.mkv"
timestamps = "top_timestamps.csv"
view = "top"
marker_id = 0
[cameras.side]
video = "side.mkv"
timestamps = "side_timestamps.csv"
view = "side"
marker_id = 1
"""


def test_good_session_loads_with_camera_specs(tmp_path):
    (tmp_path / "session.toml").write_text(GOOD)
    spec = load_session(tmp_path)
    assert set(spec.cameras) == {"top", "side"}
    assert spec.cameras["side"].marker_id == 1 and spec.cameras["top"].model == "weak_perspective"


@pytest.mark.parametrize(
    "text,match",
    [
        (None, "no session.toml"),
        ('name = "s"\n', "no \\[cameras"),
        (GOOD.replace("marker_id = 1", "marker_idd = 1"), "did you mean 'marker_id'"),
        (GOOD.replace('view = "side"', 'view = "sidee"'), "did you mean 'side'"),
    ],
)
def test_bad_session_files_give_one_line_errors(tmp_path, text, match):
    if text is not None:
        (tmp_path / "session.toml").write_text(text)
    with pytest.raises(CalibError, match=match) as exc:
        load_session(tmp_path)
    assert "\n" not in str(exc.value)


def test_missing_folder(tmp_path):
    with pytest.raises(CalibError, match="session folder not found"):
        load_session(tmp_path / "nope")
