"""The progress display every long command shows."""

from __future__ import annotations

import io

from coloradar.progress import Progress, StageProgress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_stream_gets_each_state_once_with_rate_and_eta():
    out = io.StringIO()
    bar = Progress(4, "run0", stream=out, min_interval=0.0)
    for _ in range(4):
        bar.update(1)
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[-1].startswith("run0 [") and "4/4 frames" in lines[-1]
    assert "frames/s" in lines[-1] and "ETA" in lines[-1]
    assert sum("4/4" in ln for ln in lines) == 1  # the final state is not repeated by close()


def test_callback_form_on_a_terminal_ends_its_line_once():
    out = _Tty()
    bar = Progress(0, "lidar frames", stream=out, min_interval=0.0)
    for k in range(1, 6):
        bar(k, 5)
    bar.close()
    text = out.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n")
    assert "\r" in text and "5/5 frames" in text.rsplit("\r", 1)[-1]


def test_failures_are_counted_and_shown():
    out = io.StringIO()
    with Progress(3, "x", stream=out, min_interval=0.0) as bar:
        bar.update(2)
        bar.update(1, failed=1)
    assert "3/3" in out.getvalue().splitlines()[-1] and "1 failed" in out.getvalue()


def test_stage_progress_shows_every_stage_on_one_line():
    out = io.StringIO()
    prog = StageProgress("simulate", stream=out)
    prog("lidar", 2, 2)
    prog("cascade", 3, 3)
    prog.close()
    last = out.getvalue().splitlines()[-1]
    assert last == "simulate: lidar 2/2  cascade 3/3"


def test_no_eta_until_a_rate_after_the_first_unit_is_known(monkeypatch):
    # A one-second job of 485 frames whose first frame paid 1 s of start-up once read
    # "ETA 08:05": the first unit's time says nothing of the rate.
    clock = [100.0]
    monkeypatch.setattr("coloradar.progress.time.perf_counter", lambda: clock[0])
    out = _Tty()                      # redrawn at every update
    bar = Progress(485, "run0", stream=out, min_interval=0.0)
    clock[0] += 1.0                   # start-up, then the first frame
    bar.update(1)
    assert "ETA" not in out.getvalue().rsplit("\r", 1)[-1]
    clock[0] += 0.1                   # 99 frames in 0.1 s: 990 frames/s after start-up
    bar.update(99)
    last = out.getvalue().rsplit("\r", 1)[-1]
    assert "ETA 00:00" in last        # 385 frames at 990/s: 0.39 s, not 6 minutes
    assert abs(bar.eta() - 385 / 990) < 1e-9
    clock[0] += 0.5
    bar.update(385)
    assert bar.eta() == 0.0 and "ETA 00:00" in out.getvalue().rsplit("\r", 1)[-1]
