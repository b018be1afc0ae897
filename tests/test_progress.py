"""Progress lines: stages with elapsed time, a heartbeat in silence, nothing outside a session or with --quiet."""

from __future__ import annotations

import io
import time

import pytest

from dynid import _progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_outside_a_session_nothing_is_printed(capsys):
    with _progress.stage("fitting"):
        _progress.advance(1, 2)
        _progress.say("a line")
    assert capsys.readouterr() == ("", "")


def test_stage_lines_and_heartbeat_name_the_current_step(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    out = io.StringIO()
    s = _progress.Session("identify", stream=out, heartbeat=0.3).start()
    _progress._SESSIONS.append(s)
    try:
        with _progress.stage("a quick step"):  # shorter than SHOW_AFTER_S: never printed
            time.sleep(0.2)
        with _progress.stage("fitting the friction", total=4):
            _progress.advance(2)
            time.sleep(2.0)  # shown after 1 s, then the heartbeat with the count and an estimate
        _progress.say("[2/2] the verdict")
        time.sleep(1.8)
    finally:
        _progress._SESSIONS.remove(s)
        s.stop()
    lines = out.getvalue().splitlines()
    assert lines[0] == "dynid identify: fitting the friction...", lines
    assert not any("quick" in ln for ln in lines)
    beats = [ln for ln in lines if ln.startswith("dynid identify: fitting the friction: 2/4")]
    assert beats and "left" in beats[0], lines
    assert any(ln.startswith("dynid identify: fitting the friction: done (2.") for ln in lines), lines
    # after the stage, the line said is shown, then repeated by the heartbeat with its elapsed time
    assert "dynid identify: [2/2] the verdict..." in lines
    assert lines[-1].startswith("dynid identify: [2/2] the verdict ("), lines
    assert "\r" not in out.getvalue() and "\033" not in out.getvalue()  # no control characters when piped


def test_a_terminal_gets_one_redrawn_bar(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.setenv("TERM", "xterm")
    out = _Tty()
    s = _progress.Session("fleet", stream=out, heartbeat=0.3).start()
    _progress._SESSIONS.append(s)
    try:
        with _progress.stage("identifying recordings", total=10):
            _progress.advance(5)
            time.sleep(1.8)
    finally:
        _progress._SESSIONS.remove(s)
        s.stop()
    text = out.getvalue()
    assert "\r\033[K" in text and "[##########..........] 5/10" in text


def test_an_error_at_once_is_the_only_line(tmp_path, capfd):
    from dynid.cli import main

    code = main(["identify", "--robot", "ur5", "--data", str(tmp_path / "none.csv"), "--out", str(tmp_path / "M.json")])
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("dynid identify: error:"), err


def test_ci_gets_plain_lines_even_on_a_terminal(monkeypatch):
    monkeypatch.setenv("CI", "true")
    s = _progress.Session("demo", stream=_Tty())
    assert not s.terminal


@pytest.mark.parametrize("quiet", [False, True])
def test_quiet_silences_the_progress_not_the_results(tmp_path, capfd, quiet):
    from dynid.cli import main

    out = tmp_path / "T.json"
    argv = ["excite", "--robot", "ur5", "--criterion", "seed", "--harmonics", "2", "--out", str(out)]
    code = main([*argv, "--quiet"] if quiet else argv)
    captured = capfd.readouterr()
    assert code == 0 and out.is_file()
    assert "cond" in captured.out  # the summary stays on stdout
    assert ("dynid excite:" in captured.err) is not quiet
