"""Every code block and shown output of README.md and docs/*.md, run against simulated data, so
that the docs cannot drift from what the code does.

- ```python blocks run in order, one namespace per Markdown file, in a scratch folder holding
  ``data`` (the shared simulated dataset, below) and nothing else: a block a user copies runs
  as written on what ``coloradar simulate`` (or ``coloradar demo``) writes, with no real-data
  name to edit (a real name may appear in a comment). A block whose optional package (torch,
  ...) is not installed is skipped, saying so.
- Transcripts (``$ coloradar ...`` lines, each followed by its output) run in a scratch folder
  of their own that holds ``data``, and what each command prints is compared with what the
  doc shows (rules in ``tests/_docblocks.py``: text, names, columns and counts exact, figures
  within 5 %, timings and rates free).
- Blocks that cannot run here carry ``<!-- doc-test: skip (reason) -->`` on the line before
  them; blocks whose output depends on optional extras (the demo's heatmap engine and
  pictures) carry ``<!-- doc-test: needs (numba, matplotlib) -->`` and run where those import;
  every other block must run.

The shared dataset is made once, by the docs' own command
``coloradar simulate data --scene courtyard --duration 6 --seed 1`` (its output is compared
with the doc's like any other command's): the run ``data/11_21_2026_sim_courtyard_run1`` (the
date is the simulator's fixed default start time) and ``data/calib``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import shlex
import warnings
from pathlib import Path

import pytest

from _docblocks import Block, compare_output, extract_blocks, line_matches
from coloradar.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
DOC_FILES = ["README.md", *sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))]
SHARED_SIM = "coloradar simulate data --scene courtyard --duration 6 --seed 1"
SIM_RUN = "11_21_2026_sim_courtyard_run1"
OPTIONAL = {"torch", "rerun", "distributed", "dask"}

# Blocks of docs owned by other work in progress that do not agree with the code yet, keyed by
# (file, first line of the block): run, and reported as xfail while they fail; one that runs
# as shown fails the test until its entry is removed.
KNOWN_DRIFT: dict[tuple[str, str], str] = {
}

BLOCKS = [b for f in DOC_FILES for b in extract_blocks(ROOT / f, f)]


def _run_coloradar(argv: list[str]) -> tuple[int, str, str]:
    """``coloradar ARGV`` in this process: exit code, stdout, stderr (with the warnings a
    terminal would show)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            warnings.catch_warnings():
        warnings.resetwarnings()
        warnings.showwarning = (lambda msg, cat, fn, ln, file=None, line=None:
                                err.write(warnings.formatwarning(msg, cat, fn, ln, line)))
        try:
            code = main(argv)
        except SystemExit as exc:          # argparse: --help, usage errors
            code = exc.code if isinstance(exc.code, int) else 1
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def shared(tmp_path_factory) -> dict:
    base = tmp_path_factory.mktemp("docs")
    cwd = os.getcwd()
    os.chdir(base)
    try:
        sim = _run_coloradar(shlex.split(SHARED_SIM)[1:])
    finally:
        os.chdir(cwd)
    assert sim[0] == 0, sim[2]
    return {"base": base, "data": base / "data", "outputs": {SHARED_SIM: sim},
            "namespaces": {}, "ran": set()}


def _listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def _scratch(shared: dict, name: str) -> Path:
    d = shared["base"] / "scratch" / name.replace("/", "_").replace(":", "_")
    if not d.exists():
        d.mkdir(parents=True)
        (d / "data").symlink_to(shared["data"], target_is_directory=True)
    return d


def _python_source(block: Block, shared: dict) -> str:
    src = "\n".join(block.body)
    return src  # as a user copies it: no name is mapped


def _exec_python(block: Block, shared: dict, monkeypatch) -> None:
    d = _scratch(shared, block.file)
    monkeypatch.chdir(d)
    # Run as a script is: examples guarded by `if __name__ == "__main__":` run too.
    ns = shared["namespaces"].setdefault(block.file, {"__name__": "__main__"})
    # Blocks of one file build on each other: run the earlier ones first (when this one was
    # selected alone).
    for earlier in BLOCKS:
        if earlier.file == block.file and earlier.line < block.line and earlier.kind == "python" \
                and earlier.id not in shared["ran"]:
            shared["ran"].add(earlier.id)
            with contextlib.suppress(Exception):
                exec(compile(_python_source(earlier, shared), earlier.id, "exec"), ns)
    shared["ran"].add(block.id)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(_python_source(block, shared), block.id, "exec"), ns)
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.split(".")[0] in OPTIONAL:
            pytest.skip(f"{block.id} needs the optional package {exc.name}")
        raise


def _run_transcript(block: Block, shared: dict, monkeypatch) -> None:
    d = _scratch(shared, block.id)
    monkeypatch.chdir(d)
    before = _listing(shared["data"])
    for cmd, shown in block.commands:
        argv = shlex.split(cmd, comments=True)
        if not argv or argv[0] != "coloradar":
            pytest.fail(f"{block.id}: `{cmd}` is not a coloradar command the test can run; "
                        "mark the block <!-- doc-test: skip (reason) -->")
        key = " ".join(argv)
        if key in shared["outputs"]:
            code, out, err = shared["outputs"][key]
        else:
            code, out, err = _run_coloradar(argv[1:])
        if code != 0 and "pip install 'coloradar[" in err:
            pytest.skip(f"{block.id}: `{cmd}` needs an optional extra: {err.strip()}")
        if code != 0 and not any(s.startswith("coloradar: error") for s in shown):
            pytest.fail(f"{block.id}: `{cmd}` exited {code}:\n{err[-2000:]}")
        problem = compare_output(shown, out.splitlines(), err.splitlines())
        if problem:
            pytest.fail(f"{block.id}: `{cmd}`: {problem}\n--- printed:\n{out}{err}")
    assert _listing(shared["data"]) == before, f"{block.id} wrote into the shared data/ folder"


@pytest.mark.parametrize("block", BLOCKS, ids=[b.id for b in BLOCKS])
def test_doc_block(block: Block, shared, monkeypatch):
    drift = KNOWN_DRIFT.get((block.file, block.body[0] if block.body else ""))
    if drift:
        try:
            _check_block(block, shared, monkeypatch)
        except (Exception, pytest.fail.Exception) as exc:
            pytest.xfail(f"{block.id}: {drift}: {str(exc).splitlines()[0][:300]}")
        pytest.fail(f"{block.id} runs as shown now: remove its KNOWN_DRIFT entry ({drift})")
    _check_block(block, shared, monkeypatch)


def _check_block(block: Block, shared: dict, monkeypatch) -> None:
    if block.kind == "skip":
        assert block.reason, f"{block.id}: a skip marker must give its reason: (reason)"
        pytest.skip(f"{block.id}: {block.reason}")
    missing = [m for m in block.needs if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"{block.id}: its output needs {', '.join(missing)} (not installed)")
    if block.kind == "unmarked":
        pytest.fail(f"{block.id}: a ```{block.lang or ''} block that is neither Python nor a "
                    "`$ coloradar ...` transcript; run it or mark it "
                    "<!-- doc-test: skip (reason) --> on the line before")
    if block.kind == "python":
        _exec_python(block, shared, monkeypatch)
    elif block.kind == "transcript":
        _run_transcript(block, shared, monkeypatch)
    else:
        pytest.fail(f"{block.id}: unknown doc-test marker {block.kind!r} (known: skip, needs)")


# -- the comparison itself ------------------------------------------------------------------------
def test_output_comparison_rules():
    shown = "  cascade/adc                   30     5.80 s   5.00 Hz  none"
    assert line_matches(shown, "  cascade/adc 30 5.93 s 5.01 Hz none")       # spacing, timing
    assert not line_matches(shown, "  cascade/adc 31 5.80 s 5.00 Hz none")    # a count
    assert not line_matches(shown, "  cascade/adc 30 5.80 s 5.40 Hz none")    # a figure, 8 %
    assert not line_matches(shown, "  cascade/heatmaps 30 5.80 s 5.00 Hz none")
    assert line_matches("60 frames in 2.2 s (27.6 frames/s; 2 workers; peak 115 MiB)",
                        "60 frames in 9.1 s (6.6 frames/s; 2 workers; peak 301 MiB)")
    assert not line_matches("60 frames in 2.2 s (2 workers)", "60 frames in 2.2 s (3 workers)")
    assert line_matches("RMSE 0.057 m/s, 98%", "RMSE 0.058 m/s, 97%")
    assert not line_matches("RMSE 0.057 m/s", "RMSE 0.070 m/s")
    assert line_matches("elapsed 00:02 ETA 00:00", "elapsed 01:13 ETA 00:09")
    assert compare_output(["a 1", "...", "c 3"], ["a 1", "b 2", "b 3", "c 3"], []) is None
    assert compare_output(["a 1", "c 3"], ["a 1", "b 2", "c 3"], []) is not None
    assert compare_output(["a 1", "bar 10/10 frames 3.1 frames/s", "c 3"], ["a 1", "c 3"],
                          ["bar 5/10 frames 1.0 frames/s", "bar 10/10 frames 2.0 frames/s"]) is None
    assert compare_output(["a 1"], ["a 1", "extra"], []) is not None


def test_markers_are_read(tmp_path):
    md = tmp_path / "x.md"
    md.write_text("text\n\n<!-- doc-test: skip (needs real data) -->\n\n```python\nimport x\n```\n"
                  "```text\n$ coloradar info data \\\n    --x\nout 1\n```\n```\nplain\n```\n")
    a, b, c = extract_blocks(md, "x.md")
    assert (a.kind, a.reason) == ("skip", "needs real data")
    assert b.kind == "transcript" and b.commands == [("coloradar info data --x", ["out 1"])]
    assert c.kind == "unmarked"


def test_copyable_python_blocks_name_no_real_dataset_path():
    """A user on the "no download" path copies a block and runs it as is: the code (comments
    aside) names what `coloradar simulate`/`demo` writes, never a real run or /data/coloradar."""
    bad = [b.id for b in BLOCKS if b.kind == "python" and any(
        name in "\n".join(ln.split("#", 1)[0] for ln in b.body)
        for name in ("/data/coloradar", "12_21_2020_"))]
    assert not bad, f"blocks that name real data outside a comment: {bad}"
