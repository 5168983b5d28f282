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


def test_session_toml_with_a_utf8_bom_loads(tmp_path):
    """A Windows editor's byte-order mark before the first key is not a TOML error."""
    (tmp_path / "session.toml").write_bytes(b"\xef\xbb\xbf" + GOOD.encode())
    assert load_session(tmp_path).name == "s"


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


# --- two cameras on one video, timestamp file or marker id (issue 19) ----------------------
def _two_cameras(folder, text):
    """A session folder with empty named files (nothing is decoded before the check)."""
    folder.mkdir(exist_ok=True)
    (folder / "session.toml").write_text(text)
    for name in ("top.mkv", "side.mkv", "top_timestamps.csv", "side_timestamps.csv"):
        (folder / name).write_text("")
    return folder


def _assert_names_both(exc, key):
    msg = str(exc.value)
    assert "\n" not in msg and "session.toml" in msg, msg
    assert "[cameras.top]" in msg and "[cameras.side]" in msg and key in msg, msg


@pytest.mark.parametrize(
    "text,key",
    [
        (GOOD.replace('video = "side.mkv"', 'video = "top.mkv"'), "same video"),
        (GOOD.replace('video = "side.mkv"', 'video = "./top.mkv"'), "same video"),
        (GOOD.replace('video = "side.mkv"', 'video = "sub/../top.mkv"'), "same video"),
        (GOOD.replace('"side_timestamps.csv"', '"top_timestamps.csv"'), "same timestamps"),
        (GOOD.replace("marker_id = 1", "marker_id = 0"), "same marker_id = 0"),
        (GOOD.replace("marker_id = 1\n", ""), "same marker_id = 0"),  # a missing id is 0
    ],
)
def test_two_cameras_sharing_a_video_timestamps_or_marker_id_are_refused(tmp_path, text, key):
    from i2ris_calib.io.session import check_cameras

    s = _two_cameras(tmp_path, text)
    (s / "sub").mkdir()
    with pytest.raises(CalibError) as exc:
        check_cameras(s, load_session(s))
    _assert_names_both(exc, key)


def test_a_symlink_to_the_other_cameras_video_is_the_same_video(tmp_path):
    from i2ris_calib.io.session import check_cameras

    s = _two_cameras(tmp_path, GOOD)
    check_cameras(s, load_session(s))  # distinct files, distinct ids: fine
    (s / "side.mkv").unlink()
    (s / "side.mkv").symlink_to(s / "top.mkv")
    with pytest.raises(CalibError) as exc:
        check_cameras(s, load_session(s))
    _assert_names_both(exc, "same video")
    assert "'top.mkv' and 'side.mkv', one file" in str(exc.value)


@pytest.mark.parametrize("command", ["track", "run"])
def test_track_and_run_refuse_one_video_for_both_cameras_before_any_work(tmp_path, capsys, command):
    """The CLI refuses with one line naming both tables; no output folder appears."""
    from i2ris_calib.cli import main

    s = _two_cameras(tmp_path / "s", GOOD.replace('video = "side.mkv"', 'video = "top.mkv"'))
    argv = [command, str(s)] + (["--out", str(tmp_path / "runs")] if command == "run" else [])
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error: ") and "[cameras.top] and [cameras.side]" in err, err
    assert "same video" in err and "give each camera its own video" in err, err
    assert not (s / "track").exists() and not (tmp_path / "runs").exists()
