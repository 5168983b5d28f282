"""The command line reads like a well-made CLI (issue 22): help without type placeholders,
flags that take no value, the exit status of --debug, what fit/diagnose print."""

import re
from pathlib import Path

import pytest

from i2ris_calib.cli import app, main

pytest_plugins = ["pytester"]

COMMANDS = sorted(c.name or c.callback.__name__.replace("_", "-") for c in app.registered_commands)

# typer's own placeholders: "<bool>", "<path>", "<list[Path]>", "{session}", "[bool]"
LEAKS = re.compile(
    r"<(bool|int|float|str|path|list\[[^>]*)>|\{[a-z_]+\}|\[(bool|int|float|str|path)\]", re.I
)


def _help(capsys, *args: str) -> str:
    assert main([*args, "--help"]) == 0
    return capsys.readouterr().out


def test_every_command_is_listed(capsys):
    out = _help(capsys)
    assert set(COMMANDS) <= set(re.findall(r"^  ([a-z-]+) ", out, re.M))
    assert len(COMMANDS) >= 11


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_help_has_no_type_placeholders(capsys, command):
    out = _help(capsys, *command.split())
    assert out.startswith("Usage: i2ris-calib ")
    assert not LEAKS.findall(out), out
    assert "<list[" not in out and "{" not in out.splitlines()[0]
    for flag in ("--help", "--force", "--signed", "--split", "--debug", "--version"):
        for line in out.splitlines():  # a flag is followed by its help text, not a value
            if re.match(rf"\s+{flag}\b", line):
                assert re.match(rf"\s+{flag}\s{{2,}}\S", line), line


@pytest.mark.parametrize(
    "command, usage",
    [
        ("run", "Usage: i2ris-calib run [OPTIONS] SESSION..."),
        ("fit", "Usage: i2ris-calib fit [OPTIONS] DATA.csv..."),
        ("diagnose", "Usage: i2ris-calib diagnose [OPTIONS] DATA.csv"),
        ("compensate", "Usage: i2ris-calib compensate [OPTIONS] FIT.json..."),
        ("report", "Usage: i2ris-calib report [OPTIONS] RUN_DIR"),
        ("track", "Usage: i2ris-calib track [OPTIONS] SESSION"),
    ],
)
def test_usage_lines_name_what_to_give(capsys, command, usage):
    assert _help(capsys, command).splitlines()[0] == usage


def test_option_values_are_named(capsys):
    out = _help(capsys, "fit")
    for text in ("--axis AXIS", "-o, --out DIR", "-c, --config PIPELINE.toml"):
        assert text in out
    assert "--model-file FINAL_MODEL.json" in out
    out = _help(capsys, "compensate")
    assert "--target TARGET.csv" in out and "-o, --out COMMANDS.csv" in out


def _option_help(out: str, option: str) -> str:
    """The help text of ``option`` (its line and the wrapped lines after it), one line."""
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if re.match(rf"\s+{option}\b", line))
    block = [lines[start]]
    for line in lines[start + 1 :]:
        if re.match(r"\s+-", line) or not line.strip():
            break
        block.append(line)
    return " ".join(" ".join(block).split())


def test_kind_lists_are_the_registrys():
    """The CLI's kind lists (written out so that --help does not import the models)
    are the registry's, in its order."""
    from i2ris_calib import cli
    from i2ris_calib.hysteresis import registry as r

    assert cli._DIRECTION_KINDS == r.MODEL_KINDS
    assert cli._SIGNED_ONLY_KINDS == tuple(k.kind for k in r.KINDS if k.factory and k.signed)
    assert cli._FIT_MODELS == r.BUILT_KINDS
    assert cli._INVERSE_MODELS == r.INVERSE_KINDS
    assert cli._DIAGNOSIS_STARTS == r.DIAGNOSIS_STARTS


def _accepted(command: str) -> tuple[str, ...]:
    """The values the command's model option accepts, from the command itself."""
    if command == "fit":
        from i2ris_calib.hysteresis.registry import BUILT_KINDS

        return (*BUILT_KINDS, "all")  # commands.fit.fit_files checks these
    if command == "compensate":
        from i2ris_calib.commands.compensate import KINDS

        return KINDS
    from i2ris_calib.commands.diagnose import STARTS

    return STARTS


@pytest.mark.parametrize(
    "command, option", [("fit", "--model"), ("compensate", "--model"), ("diagnose", "--start")]
)
def test_help_names_every_kind_the_option_accepts(capsys, command, option):
    text = _option_help(_help(capsys, command), option)
    missing = [
        k for k in _accepted(command) if not re.search(rf"(?<![\w-]){re.escape(k)}(?![\w-])", text)
    ]
    assert not missing, (command, option, text)


def test_brackets_in_help_survive(capsys):
    out = _help(capsys, "simulate")
    assert "[simulate] seed" in " ".join(out.split())


@pytest.mark.parametrize("word", ["true", "False", "1"])
def test_a_value_after_a_flag_is_a_usage_error(tmp_path, capsys, monkeypatch, word):
    monkeypatch.chdir(tmp_path)  # no folder named like the word
    rc = main(["run", "session", "--force", word, "--out", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert rc == 2
    assert f"'{word}' after --force: --force is a flag and takes no value" in err
    assert not (tmp_path / "runs").exists()


def test_a_folder_named_true_is_still_a_session(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("true").mkdir()  # a real folder: not refused as a flag value (but not a session)
    rc = main(["run", "true", "--force", "true", "--out", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert rc == 2 and "takes no value" not in err and err.startswith("error: ")


def test_debug_shows_the_traceback_and_keeps_status_2(tmp_path, capsys):
    args = ["fit", str(tmp_path / "missing.csv"), "--axis", "yaw", "--out", str(tmp_path / "o")]
    assert main(args) == 2
    plain = capsys.readouterr().err
    assert "Traceback" not in plain and plain.startswith("error: ")
    assert main(["--debug", *args]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1] == plain.strip()


def test_debug_internal_error_exits_1(monkeypatch, tmp_path, capsys):
    import i2ris_calib.io.config_io as config_io

    def boom(path):
        raise RuntimeError("bug")

    monkeypatch.setattr(config_io, "load_config", boom)
    assert main(["config"]) == 1
    assert "internal error: RuntimeError: bug" in capsys.readouterr().err
    assert main(["--debug", "config"]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_diagnose_prints_one_verdict_line():
    from i2ris_calib.diagnosis.report import verdict_line

    rec = {
        "dataset": "yaw+",
        "named_effects": ["time_delay"],
        "baseline": {"holdout_rmse_deg": 0.42},
        "final": {"holdout_rmse_deg": 0.15},
        "not_excluded": [{"effect": "backlash", "start": "egpi"}, {"effect": "backlash"}],
        "paths": {"gpi": {"named_effects": ["time_delay"]}, "egpi": {"named_effects": []}},
        "start_model": "gpi",
        "summary": "x" * 1300,
    }
    line = verdict_line(rec)
    assert line == (
        "yaw+: named time_delay (held-out RMSE 0.42 -> 0.15 deg); not told apart: backlash; "
        "gpi and egpi starts disagree (answer from gpi)"
    )
    rec.update(named_effects=[], not_excluded=[], paths={})
    assert verdict_line(rec) == "yaw+: nothing missing (held-out RMSE 0.15 deg)"


# -- tests/conftest.py: the slow tests a default run leaves out are counted --------------

SLOW_AND_FAST = """
import pytest

@pytest.mark.slow
def test_slow():
    pass

@pytest.mark.slow
def test_slower():
    pass

def test_fast():
    pass
"""


@pytest.fixture
def suite(pytester):
    pytester.makeconftest((Path(__file__).parent / "conftest.py").read_text())
    pytester.makeini("[pytest]\naddopts = -m 'not slow'\nmarkers =\n    slow: long-running\n")
    pytester.makepyfile(test_suite=SLOW_AND_FAST)
    return pytester


def test_default_run_says_how_many_slow_tests_it_left_out(suite):
    result = suite.runpytest("-p", "no:xdist")
    result.assert_outcomes(passed=1, deselected=2)
    result.stdout.fnmatch_lines(
        ["2 slow tests not run; run them with: bash scripts/test.sh -m slow"]
    )


def test_no_line_when_slow_tests_run(suite):
    result = suite.runpytest("-p", "no:xdist", "-m", "slow")
    result.assert_outcomes(passed=2, deselected=1)
    assert "slow test" not in result.stdout.str()


def test_the_count_reaches_the_xdist_controller(suite):
    pytest.importorskip("xdist")
    result = suite.runpytest_subprocess("-n", "1")
    result.stdout.fnmatch_lines(
        ["2 slow tests not run; run them with: bash scripts/test.sh -m slow"]
    )


@pytest.mark.parametrize("columns", ["80", "100"])
def test_top_level_help_shows_every_summary_whole(capsys, monkeypatch, columns):
    """Each command's one-line summary fits: no "..." cut at 80 or 100 columns."""
    monkeypatch.setenv("COLUMNS", columns)
    out = _help(capsys)
    listed = out.split("Commands:")[1].splitlines()[1:]
    assert len([line for line in listed if line.strip()]) == len(COMMANDS)
    for line in listed:
        assert "..." not in line and line.rstrip().endswith("."), line
