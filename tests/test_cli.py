import subprocess
import sys

from i2ris_calib import __version__
from i2ris_calib.cli import main


def test_version(capsys):
    assert main(["--version"]) == 0
    assert __version__ in capsys.readouterr().out


def test_bad_config_is_one_line_error(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[fit]\nno_such_key = 1\n")
    rc = main(["fit", str(tmp_path / "x.csv"), "--axis", "yaw", "--config", str(cfg)])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1
    assert "Traceback" not in err


def test_help_is_fast_and_imports_no_heavy_modules():
    code = (
        "import sys; from i2ris_calib.cli import app; "
        "heavy = [m for m in ('cv2', 'numba', 'matplotlib') if m in sys.modules]; "
        "print(','.join(heavy))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
