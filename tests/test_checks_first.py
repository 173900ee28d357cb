"""Checks before the work (issue 41, items 1-5): an output that cannot be written is refused
before any frame is read, and named as the user typed it; an empty slice, a negative duration
and every other option value out of range are usage errors said by the parser (exit 2, one
line, the option named); the command line's wording for overwriting and swapped arguments."""

from __future__ import annotations

import argparse
import builtins
import errno
import io
import os
from pathlib import Path

import pytest

from _synth import write_run
from coloradar.cli._common import cli_wording
from coloradar.cli.main import build_parser, main
from coloradar.errors import WriteError

RUN = "12_21_2020_ec_hallways_run0"


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    r = tmp_path_factory.mktemp("checks_first")
    write_run(r, RUN, n_cascade=2, n_single=6, n_lidar=4, n_imu=60, n_gt=12)
    return r


def _cli(argv, capsys) -> tuple[int, str, str]:
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:       # argparse's own checks
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, out, err


@pytest.fixture
def read_only(tmp_path, monkeypatch) -> Path:
    """A folder that behaves as one on a read-only file system (the tests run as root, whom
    ``chmod`` does not stop): creating, removing or renaming anything in it fails with EROFS,
    as the system calls do there (``unlink`` of a name that does not exist included)."""
    ro = tmp_path / "ro"
    ro.mkdir()

    def inside(path) -> bool:
        try:
            return Path(os.fsdecode(path)).resolve().is_relative_to(ro.resolve())
        except (TypeError, ValueError):
            return False

    def refuse(path):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fsdecode(path))

    def guard(real, writes=lambda *a, **k: True):
        def call(path, *args, **kwargs):
            if inside(path) and writes(*args, **kwargs):
                refuse(path)
            return real(path, *args, **kwargs)
        return call

    def open_writes(mode="r", *a, **k):
        return isinstance(mode, str) and any(c in mode for c in "wax+")

    def os_open_writes(flags, *a, **k):
        return bool(flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT))

    for name in ("mkdir", "unlink", "remove", "rmdir"):
        monkeypatch.setattr(os, name, guard(getattr(os, name)))
    monkeypatch.setattr(os, "open", guard(os.open, os_open_writes))
    for name in ("replace", "rename"):
        monkeypatch.setattr(os, name, guard(getattr(os, name)))
    monkeypatch.setattr(io, "open", guard(io.open, open_writes))
    monkeypatch.setattr(builtins, "open", guard(builtins.open, open_writes))
    return ro


def _no_work(monkeypatch) -> None:
    """Opening the run is where every command's work begins: it must not be reached."""
    import coloradar.cli.export as export
    import coloradar.cli.map as map_
    import coloradar.cli.odometry as odometry
    import coloradar.cli.plot as plot
    import coloradar.cli.slam as slam

    def work(*args, **kwargs):
        raise AssertionError("the work began before the output was checked")

    for mod in (odometry, slam, map_, plot, export):
        monkeypatch.setattr(mod, "open_sequence", work)


# -- 1: an output that cannot be written is refused before the work -------------------------------
@pytest.mark.parametrize("argv", [
    ["odometry", "{run}", "--out", "{ro}/odo"],
    ["slam", "{run}", "--out", "{ro}/slam"],
    ["map", "{run}", "--out", "{ro}/m.pcd"],
    ["map", "{run}", "--out", "{ro}/deeper/m.pcd"],
    ["plot", "{run}", "--view", "scene", "--out", "{ro}/scene.png"],
    ["export", "{run}", "{ro}/x.bag"],
    ["export", "{run}", "{ro}/x.h5"],
    ["animate", "{run}", "--out", "{ro}/v.gif"],
], ids=lambda a: " ".join(a[:1] + a[-1:]))
def test_a_read_only_output_is_refused_before_the_work(root, read_only, monkeypatch, capsys,
                                                       argv):
    if argv[0] == "plot":
        pytest.importorskip("matplotlib")        # plot needs its extra before it looks further
    _no_work(monkeypatch)
    argv = [a.format(run=root / RUN, ro=read_only) for a in argv]
    out = argv[argv.index("--out") + 1] if "--out" in argv else argv[2]
    code, _, err = _cli(argv, capsys)
    assert code == 1 and err.count("\n") == 1, err
    assert err == f"coloradar: error: {out}: cannot write (Read-only file system)\n"


@pytest.mark.parametrize("argv", [
    ["odometry", "{run}", "--out", "{f}/odo"],
    ["slam", "{run}", "--out", "{f}/slam"],
    ["map", "{run}", "--out", "{f}/m.pcd"],
    ["plot", "{run}", "--view", "scene", "--out", "{f}/scene.png"],
], ids=lambda a: a[0])
def test_an_output_under_a_file_is_refused_before_the_work(root, tmp_path, monkeypatch, capsys,
                                                           argv):
    if argv[0] == "plot":
        pytest.importorskip("matplotlib")        # plot needs its extra before it looks further
    _no_work(monkeypatch)
    (tmp_path / "afile").write_text("x")
    code, _, err = _cli([a.format(run=root / RUN, f=tmp_path / "afile") for a in argv], capsys)
    assert code == 1 and err.count("\n") == 1 and str(tmp_path / "afile") in err, err


# -- 2: a failed atomic write names the user's path, not its temporary file -----------------------
def test_a_failed_write_names_the_users_path_not_the_temporary_file(read_only):
    from coloradar.formats.atomic import atomic_write_bytes

    target = read_only / "scene.png"
    with pytest.raises(WriteError) as exc:
        atomic_write_bytes(target, b"png")
    assert str(exc.value) == f"{target}: cannot write (Read-only file system)"


def test_a_failed_figure_and_bag_name_the_users_path(root, read_only):
    pytest.importorskip("matplotlib")
    pytest.importorskip("rosbags")
    import matplotlib.pyplot as plt

    import coloradar as cr
    from coloradar.interop.bag_export import export_bag
    from coloradar.viz import save_figure

    fig = plt.figure()
    with pytest.raises(WriteError, match=r"^\S*scene\.png: cannot write") as exc:
        save_figure(fig, read_only / "scene.png")
    plt.close(fig)
    assert ".tmp" not in str(exc.value)
    seq = cr.open_sequence(root / RUN)
    with pytest.raises(WriteError) as exc:
        export_bag(seq, read_only / "x.bag", "ros1", streams=["imu"])
    assert str(exc.value) == f"{read_only / 'x.bag'}: cannot write (Read-only file system)"


# -- 3: an empty slice, a negative duration -------------------------------------------------------
@pytest.mark.parametrize("frames", ["10:5", "3:3", ":0", "-2:-5", "5:0"])
def test_an_empty_or_reversed_frame_slice_is_a_usage_error(root, tmp_path, capsys, frames):
    code, _, err = _cli(["process", root / RUN, "--out", tmp_path / "p", "--frames", frames,
                         "--jobs", 1], capsys)
    assert code == 2 and err.count("\n") == 1 and "argument --frames" in err, err
    assert not (tmp_path / "p").exists()


def test_a_negative_duration_is_a_usage_error(root, tmp_path, capsys):
    code, _, err = _cli(["odometry", root / RUN, "--out", tmp_path / "o", "--duration", "-3"],
                        capsys)
    assert code == 2 and err.count("\n") == 1 and "argument --duration" in err, err


# -- 4: every numeric option: 0, -1 and an absurd value -------------------------------------------
# (command, option, value) the parser accepts, and why; every other value of the walk below
# must be refused by the parser itself. A new numeric option must be placed here or refused.
ACCEPTED = {
    # 0 is a value these options mean
    **{(c, o, "0"): "zero is meant" for c, o in [
        ("animate", "--start"), ("map", "--start"), ("map", "--min-range"),
        ("odometry", "--start"), ("odometry", "--time-offset"), ("odometry", "--seed"),
        ("slam", "--seed"), ("simulate", "--seed"), ("simulate", "--speed"),
        ("simulate", "--rest"), ("simulate", "--imu-noise"), ("simulate", "--radar-time-offset"),
        ("demo", "--seed"), ("benchmark", "--seed"), ("plot", "--frame"),
        ("calibrate coupling", "--min-speed"), ("import-capture", "--start-time")]},
    # -1 is a value these options mean
    ("plot", "--frame", "-1"): "the last frame",
    ("odometry", "--time-offset", "-1"): "an offset of either sign, within 1 s",
    # large values that mean "everything" or whose emptiness only the data can tell
    **{(c, o, "1000000000"): "large but meaningful" for c, o in [
        ("map", "--stride"), ("odometry", "--stride"), ("odometry", "--seed"),
        ("odometry", "--min-inliers"), ("slam", "--seed"), ("simulate", "--seed"),
        ("demo", "--seed"), ("benchmark", "--seed"), ("plot", "--frame"),
        ("process", "--chunk-size"), ("score", "--min-hits"), ("score", "--bin-columns"),
        ("export", "--min-hits"), ("calibrate coupling", "--max-frames"),
        ("calibrate phase", "--max-frames")]},
    **{(c, o, "1e9"): "large but meaningful" for c, o in [
        ("animate", "--start"), ("animate", "--duration"), ("animate", "--extent"),
        ("map", "--start"), ("map", "--duration"), ("map", "--voxel"), ("map", "--min-range"),
        ("map", "--max-range"), ("map-score", "--threshold"), ("map-score", "--voxel"),
        ("odometry", "--imu-noise-scale"), ("odometry", "--threshold"),
        ("odometry", "--gyro-bias-window"), ("odometry", "--start"), ("odometry", "--duration"),
        ("plot", "--extent"), ("plot", "--max-range"), ("score", "--threshold"),
        ("score", "--cell"), ("score", "--voxel-size"), ("export", "--cell"),
        ("export", "--voxel-size"), ("evaluate", "--distances"), ("evaluate", "--drift-lengths"),
        ("benchmark", "--distances"), ("benchmark", "--drift-lengths"), ("simulate", "--laps"),
        ("simulate", "--imu-noise"), ("slam", "--keyframe-distance"),
        ("slam", "--keyframe-angle"), ("calibrate coupling", "--min-speed"),
        ("calibrate phase", "--max-speed"), ("import-capture", "--start-time")]},
}


def _parsers() -> dict[str, argparse.ArgumentParser]:
    """Every (sub-)command's parser by its name as typed (``calibrate phase``)."""
    found: dict[str, argparse.ArgumentParser] = {}

    def walk(parser: argparse.ArgumentParser, prefix: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, f"{prefix} {name}".strip())
        if prefix:
            found[prefix] = parser
    walk(build_parser(), "")
    return found


def _required_args(parser: argparse.ArgumentParser) -> list[str]:
    """Values for a parser's positionals and required options (their first choice, or a name)."""
    argv: list[str] = []
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction) or a.nargs in ("?", "*"):
            continue
        if not a.option_strings or a.required:
            value = str(next(iter(a.choices))) if a.choices else "x"
            argv += ([a.option_strings[0]] if a.option_strings else []) + [value]
    for group in parser._mutually_exclusive_groups:
        if group.required:
            argv += [group._group_actions[0].option_strings[0], "x"]
    return argv


def _numeric_options():
    for cmd, parser in _parsers().items():
        for a in parser._actions:
            if not a.option_strings or a.type is None or a.type in (str, Path):
                continue
            probe = [a.type(v) for v in ("1", "2.5") if _parses(a.type, v)]
            if probe and all(isinstance(v, (int, float)) for v in probe):
                big = "1000000000" if _parses(a.type, "1") and not _parses(a.type, "2.5") \
                    else "1e9"
                yield cmd, a.option_strings[0], big


def _parses(kind, text: str) -> bool:
    try:
        kind(text)
    except (ValueError, TypeError, argparse.ArgumentTypeError):
        return False
    return True


NUMERIC = list(_numeric_options())


def test_the_walk_finds_the_numeric_options():
    names = {(c, o) for c, o, _ in NUMERIC}
    assert {("odometry", "--stride"), ("simulate", "--duration"), ("map", "--voxel"),
            ("process", "--jobs"), ("animate", "--fps"), ("calibrate phase", "--max-frames"),
            ("export", "--min-hits")} <= names
    assert len(names) > 50


@pytest.mark.parametrize("cmd,option,big", NUMERIC, ids=lambda x: str(x))
def test_every_numeric_option_refuses_zero_negative_and_absurd_values_at_once(
        cmd, option, big, capsys):
    parser = _parsers()[cmd]
    for value in ("0", "-1", big, "nan"):
        argv = [*_required_args(parser), f"{option}={value}"]
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            err = capsys.readouterr().err
            assert exc.code == 2, (value, err)
            assert err.count("\n") == 1 and err.startswith("coloradar: error: "), err
            assert f"argument {option}" in err and "usage:" not in err, err
            continue
        assert (cmd, option, value) in ACCEPTED, f"{cmd} {option} {value} is accepted"


@pytest.mark.parametrize("argv,option", [
    (["odometry", "{run}", "--out", "{tmp}/o", "--stride", "0"], "--stride"),
    (["simulate", "{tmp}/s", "--duration", "1e9"], "--duration"),
    (["export", "{run}", "{tmp}/x.h5", "--products", "foo"], "--products"),
    (["process", "{run}", "--out", "{tmp}/o", "--set", "foo=1"], "--set"),
    (["process", "{run}", "--out", "{tmp}/o", "--jobs", "0"], "--jobs"),
    (["map", "{run}", "--out", "{tmp}/o.pcd", "--voxel", "-1"], "--voxel"),
    (["animate", "{run}", "--out", "{tmp}/o.gif", "--fps", "0"], "--fps"),
    (["plot", "{run}", "--view", "scene", "--out", "{tmp}/o.png", "--dpi", "1000000000"],
     "--dpi"),
    (["simulate", "{tmp}/s", "--duration", "2", "--rest", "5"], "--rest"),
])
def test_bad_option_values_are_one_line_usage_errors(root, tmp_path, capsys, argv, option):
    code, _, err = _cli([a.format(run=root / RUN, tmp=tmp_path) for a in argv], capsys)
    assert code == 2 and err.count("\n") == 1 and option in err and "usage:" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_misspelt_setting_lists_the_close_names_only(root, tmp_path, capsys):
    code, _, err = _cli(["process", root / RUN, "--out", tmp_path / "o", "--set", "foo=1"],
                        capsys)
    assert code == 2 and "cfar_guard" not in err and "range_window" not in err, err
    code, _, err = _cli(["process", root / RUN, "--out", tmp_path / "o", "--set", "pfaa=1"],
                        capsys)
    assert code == 2 and "did you mean pfa?" in err and "cfar_guard" not in err, err


# -- 5: the command line's wording --------------------------------------------------------------
def test_overwrite_said_option_first_reads_as_the_option():
    msg = "out: exists; pass --overwrite (overwrite=True) to replace a run written by an import"
    assert cli_wording(msg) == "out: exists; pass --overwrite to replace a run written by an import"


def test_swapped_export_arguments_are_asked_about(root, tmp_path, capsys):
    bag = tmp_path / "run.bag"
    bag.write_bytes(b"#ROSBAG V2.0\n")
    for first in (bag, tmp_path / "missing.bag"):
        code, _, err = _cli(["export", first, root / RUN], capsys)
        assert code == 1 and "are the arguments swapped?" in err, err
        assert err.count("\n") == 1
