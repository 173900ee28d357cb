"""Code blocks of the Markdown docs, and the comparison of a shown output with a printed one
(used by tests/test_docs.py).

A block is a fenced code block (```lang ... ```). The HTML comment
``<!-- doc-test: skip (reason) -->`` on the last non-blank line before a block marks a block
that cannot run here (real data, a Dask cluster, ``pip install``, a benchmark); the reason is
required. ``<!-- doc-test: needs (numba, matplotlib) -->`` marks a block whose output depends
on optional extras: it runs where those modules import, and is skipped elsewhere. Every other
block must be a ```python block (executed) or a transcript: lines
``$ command`` each followed by the output it prints (run, and the output compared).

Output comparison, line by line, whitespace runs ignored: words, punctuation, names and
integers must be equal; numbers with a decimal point (and percentages) may differ by 5 % or two
units of their last shown digit; timings and speeds (a number followed by ``s``, ``ms``, a
``…/s`` rate, ``MiB``, or a ``mm:ss`` clock) may take any value. A shown line ``...`` (or
``…``) stands for any number of printed lines. Shown lines are matched against stdout; a shown
line that is not the next stdout line may match a stderr line (a progress line), and stderr
lines that are not shown are ignored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

MARKER = re.compile(r"^\s*<!--\s*doc-test:\s*(?P<kind>[a-z-]+)\s*(?:\((?P<reason>.*)\))?\s*-->\s*$")
FENCE = re.compile(r"^(?P<indent>\s*)```(?P<lang>[\w+-]*)\s*$")


@dataclass(frozen=True)
class Block:
    """One fenced block of a Markdown file."""

    file: str               # path relative to the repository root
    line: int               # 1-based line of the opening fence
    lang: str
    body: tuple[str, ...]
    marker: str | None      # "skip", or None
    reason: str

    @property
    def commands(self) -> list[tuple[str, list[str]]]:
        """``(command, shown output lines)`` of a transcript; ``\\`` continues a command."""
        out: list[tuple[str, list[str]]] = []
        lines = list(self.body)
        i = 0
        while i < len(lines):
            ln = lines[i]
            if ln.startswith("$ "):
                cmd = ln[2:]
                while cmd.rstrip().endswith("\\") and i + 1 < len(lines):
                    i += 1
                    cmd = cmd.rstrip()[:-1].rstrip() + " " + lines[i].strip()
                out.append((cmd, []))
            elif out:
                out[-1][1].append(ln)
            i += 1
        return out

    @property
    def needs(self) -> list[str]:
        """Modules a ``<!-- doc-test: needs (numba, matplotlib) -->`` block needs: its output
        depends on optional extras, so it is skipped where one is missing."""
        if self.marker != "needs":
            return []
        return [m.strip() for m in self.reason.split(",") if m.strip()]

    @property
    def kind(self) -> str:
        if self.marker and self.marker != "needs":
            return self.marker
        if self.lang == "python":
            return "python"
        if any(ln.startswith("$ ") for ln in self.body):
            return "transcript"
        return "unmarked"

    @property
    def id(self) -> str:
        return f"{self.file}:{self.line}"


def extract_blocks(path: Path, rel: str) -> list[Block]:
    """Every fenced block of ``path`` (``rel``: its name in test ids and messages)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        start, indent = i, len(m.group("indent"))
        j = i + 1
        while j < len(lines) and not re.match(r"^\s*```\s*$", lines[j]):
            j += 1
        body = tuple(ln[indent:] if ln[:indent].isspace() else ln for ln in lines[start + 1:j])
        k = start - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        mk = MARKER.match(lines[k]) if k >= 0 else None
        blocks.append(Block(rel, start + 1, m.group("lang"), body,
                            mk.group("kind") if mk else None,
                            (mk.group("reason") or "").strip() if mk else ""))
        i = j + 1
    return blocks


# -- comparing printed output with shown output ---------------------------------------------
_TOKEN = re.compile(r"\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?(?![\w.])|\d+|[^\W\d]+|\S", re.UNICODE)
_NUMBER = re.compile(r"\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?$")
_FREE_UNITS = {"s", "ms", "MiB", "GiB", "KiB", "min"}
_WORK_UNITS = {"frames", "messages", "clouds", "scans", "samples", "chunks", "runs", "poses"}


def tokens(line: str) -> list[str]:
    return _TOKEN.findall(line)


def _is_number(tok: str) -> bool:
    return bool(_NUMBER.match(tok)) and tok[0].isdigit()


def _free(toks: list[str], i: int) -> bool:
    """Whether number ``i`` is a timing or speed (any value accepted)."""
    nxt = toks[i + 1:i + 5]
    prev = toks[i - 1] if i else ""
    if nxt[:1] and nxt[0] in _FREE_UNITS:
        return True
    if prev == ":" or nxt[:1] == [":"]:          # 00:02, 1:02:03
        return True
    # a processing speed: 30.8 frames/s, 694 messages/s, 51.4 point clouds/s (not m/s)
    for k in range(1, min(3, len(nxt) - 1)):
        if nxt[k] == "/" and nxt[k + 1] == "s" and nxt[k - 1] in _WORK_UNITS \
                and all(t.isalpha() for t in nxt[:k]):
            return True
    return False


def _number(tok: str) -> float:
    return float(tok.replace(",", ""))


def _close(shown: str, got: str, percent: bool) -> bool:
    a, b = _number(shown), _number(got)
    if "." not in shown and "e" not in shown and not percent:
        return a == b                                       # counts, names, sizes: exact
    decimals = len(shown.split(".")[1]) if "." in shown else 0
    # In units of the last shown digit, rounded: 3.1 against 2.9 is two units, whatever the
    # binary rounding of their difference.
    return abs(a - b) <= 0.05 * abs(a) or round(abs(a - b) * 10.0**decimals, 6) <= 2


def line_matches(shown: str, got: str) -> bool:
    """Whether a printed line ``got`` agrees with the shown line ``shown`` (rules above)."""
    ts, tg = tokens(shown), tokens(got)
    if len(ts) != len(tg):
        return False
    for i, (a, b) in enumerate(zip(ts, tg, strict=True)):
        if _is_number(a) and _is_number(b):
            if _free(ts, i):
                continue
            if not _close(a, b, percent=ts[i + 1:i + 2] == ["%"]):
                return False
        elif a != b:
            return False
    return True


def _is_gap(line: str) -> bool:
    return line.strip() in ("...", "…")


def compare_output(shown: list[str], stdout: list[str], stderr: list[str]) -> str | None:
    """None when the printed output agrees with the shown one, else what differs."""
    shown = [s for s in shown if s.strip()]
    out = [s for s in stdout if s.strip()]
    err = [s for s in stderr if s.strip()]
    i = 0
    gap = False
    for s in shown:
        if _is_gap(s):
            gap = True
            continue
        if i < len(out) and line_matches(s, out[i]):
            i += 1
            gap = False
            continue
        if any(line_matches(s, e) for e in err):
            continue
        if gap:
            j = next((j for j in range(i, len(out)) if line_matches(s, out[j])), None)
            if j is not None:
                i, gap = j + 1, False
                continue
        got = out[i] if i < len(out) else "<end of output>"
        return f"shown line\n    {s}\ndoes not match the printed line\n    {got}"
    if i < len(out) and not gap:
        return "printed lines that are not shown:\n    " + "\n    ".join(out[i:i + 5])
    return None
