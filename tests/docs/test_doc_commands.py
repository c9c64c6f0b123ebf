"""The commands and snippets of README.md and docs/*.md run as written.

Every fenced ```bash and ```python block runs, in page order, in one scratch folder per page that looks like
the repository root (configs/, tasks/, examples/ ... linked, models/ copied, nothing written back): a later
block may use what an earlier one made, as a reader following the page would. A block that is expensive or
needs data, hardware or an install says so on the line above its fence:

    <!-- doc-test: skip (needs data/supermag.npz) -->

and is not run. The `tactile-manip ...` commands of every bash block, skipped ones included, are parsed by the
real command-line parser with exact option names (no run), so a renamed option fails here even where nothing
runs. Inline
`tactile-manip ...` commands in the prose are parsed the same way (a partial mention, missing required
options, is fine there). docs/results/ holds measured results and their reproduction commands (hours of
training), and is not run.

The missing-extra lines that pages quote (in plain fenced blocks) are compared with what the commands print
with the package hidden.

One page, or one page's parse check: `pytest tests/docs -k "page_blocks_run and collection"`.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = ["README.md", *sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))]
LINKED = ("configs", "tasks", "examples", "benchmarks", "firmware", "docs", "README.md", "pyproject.toml")
COPIED = ("models",)
LANGUAGES = ("bash", "python")
TIMEOUT_S = 300
# never run unmarked: they change the environment the tests run in, or run the tests themselves
UNSAFE = re.compile(r"\b(pip|uv|conda)\s+install\b|\bpytest\b|\bsudo\b")
SKIP = re.compile(r"<!--\s*doc-test:\s*skip\s*\((?P<reason>[^)]+)\)\s*-->")
FENCE = re.compile(r"^```(?P<lang>[\w-]*)\s*$")


@dataclass(frozen=True)
class Block:
    """One fenced code block of a page."""

    page: str
    line: int  # 1-based line of the opening fence
    lang: str
    code: str
    skip: str | None  # the reason of its doc-test skip marker, None when it runs

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def blocks(page: str, text: str) -> list[Block]:
    """The fenced blocks of ``text`` (a page's markdown) in order, with their skip markers."""
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), None)
        if end is None:
            raise ValueError(f"{page}:{i + 1}: code fence never closed")
        above = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
        marker = SKIP.search(above)
        out.append(Block(page, i + 1, m["lang"], "\n".join(lines[i + 1:end]) + "\n",
                         marker["reason"].strip() if marker else None))
        i = end + 1
    return out


def workspace(tmp: Path) -> Path:
    """A folder that looks like the repository root to the commands, writing nothing back."""
    for name in LINKED:
        (tmp / name).symlink_to(ROOT / name)
    for name in COPIED:
        shutil.copytree(ROOT / name, tmp / name)
    return tmp


def environment() -> dict[str, str]:
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    # `python` and `tactile-manip` of the environment running the tests come first
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    return env


def unsafe_code(block: Block) -> bool:
    """Whether the block (its code, not its comments) installs packages or runs the tests."""
    code = re.sub(r"(^|\s)#.*", "", block.code) if block.lang == "bash" else block.code
    return bool(UNSAFE.search(code))


def run_block(block: Block, cwd: Path) -> subprocess.CompletedProcess:
    if block.lang == "python":
        script = cwd / f"_doc_block_{block.line}.py"
        script.write_text(block.code)
        argv = [sys.executable, script.name]
    else:
        argv = ["bash", "-e", "-c", block.code]
    return subprocess.run(argv, cwd=cwd, env=environment(), capture_output=True, text=True, timeout=TIMEOUT_S,
                          stdin=subprocess.DEVNULL)


def _tail(text: str, n: int = 25) -> str:
    return "\n".join(text.strip().splitlines()[-n:])


# --- fenced blocks ---------------------------------------------------------------------------------------------
def test_pages_have_blocks_and_markers_parse():
    """The extraction sees the README's blocks, and every marker is well formed and above a block."""
    readme = blocks("README.md", (ROOT / "README.md").read_text())
    assert {b.lang for b in readme} >= {"bash", "python"}
    for page in PAGES:
        text = (ROOT / page).read_text()
        marked = {b.line for b in blocks(page, text) if b.skip is not None}
        stray = [n + 1 for n, line in enumerate(text.splitlines()) if "doc-test" in line and not SKIP.search(line)]
        assert not stray, f"{page}: malformed doc-test marker at line(s) {stray}; write <!-- doc-test: skip (why) -->"
        assert len(marked) == text.count("doc-test: skip"), f"{page}: a doc-test marker is not right above a fence"


def test_marker_and_extraction():
    text = ("intro\n\n```bash\necho 1\n```\n<!-- doc-test: skip (needs a robot) -->\n\n```python\nx = 1\n```\n"
            "```text\nno\n```\n")
    got = blocks("p.md", text)
    assert [(b.line, b.lang, b.skip) for b in got] == [(3, "bash", None), (8, "python", "needs a robot"),
                                                       (11, "text", None)]
    assert got[0].code == "echo 1\n"


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_page_blocks_run(page, tmp_path):
    todo = [b for b in blocks(page, (ROOT / page).read_text()) if b.lang in LANGUAGES and b.skip is None]
    unsafe = [b.where for b in todo if unsafe_code(b)]
    assert not unsafe, (f"{', '.join(unsafe)}: installs packages or runs the tests; mark it "
                        "<!-- doc-test: skip (installs packages) --> (nothing of this page was run)")
    if not todo:
        pytest.skip(f"{page}: no runnable block")
    cwd = workspace(tmp_path)
    for block in todo:
        try:
            done = run_block(block, cwd)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{block.where} ({block.lang}) ran past {TIMEOUT_S} s; mark it "
                        "<!-- doc-test: skip (why) --> if it is meant to be long")
        assert done.returncode == 0, (f"{block.where} ({block.lang}) failed with status {done.returncode}:\n"
                                      f"{block.code}\n--- stderr ---\n{_tail(done.stderr)}\n--- stdout ---\n"
                                      f"{_tail(done.stdout, 10)}")


def test_installs_are_never_run_unmarked():
    assert UNSAFE.search('pip install -e ".[serial]"') and UNSAFE.search("python -m pytest tests/x")
    assert not UNSAFE.search("tactile-manip simulate --out data/pip_install_notes.npz")
    commented = blocks("p.md", '```bash\ntactile-manip import --arrays x.h5 --out d.npz  # pip install -e ".[hdf5]"\n'
                                '```\n')
    assert not unsafe_code(commented[0])
    assert unsafe_code(blocks("p.md", "```bash\ntrue && pip install x  # quietly\n```\n")[0])


def test_failing_block_is_reported_with_its_place(tmp_path):
    block = blocks("x.md", "a\n\n```bash\ntrue\nfalse\n```\n")[0]
    assert run_block(block, tmp_path).returncode == 1 and block.where == "x.md:3"
    snippet = blocks("x.md", "```python\nraise SystemExit('no model')\n```\n")[0]
    assert "no model" in run_block(snippet, tmp_path).stderr


# --- inline commands -------------------------------------------------------------------------------------------
INLINE = re.compile(r"`(tactile-manip [^`]+)`")
PARTIAL = re.compile(r"the following arguments are required|one of the arguments .* is required")


def inline_commands(page: str, text: str) -> list[tuple[str, str]]:
    """(page:line, command) of each concrete inline `tactile-manip ...` of the prose (outside fences).

    Synopses ([optional], a|b alternatives, ...) and placeholders in capitals (N, RUN_DIR) are not concrete.
    """
    out, fenced = [], False
    for n, line in enumerate(text.splitlines(), 1):
        if line.startswith("```"):
            fenced = not fenced
            continue
        out += [(f"{page}:{n}", cmd) for cmd in INLINE.findall("" if fenced else line)
                if concrete(cmd, shlex.split(cmd))]
    return out


def concrete(text: str, tokens: list[str]) -> bool:
    """Whether a command is concrete, not a synopsis ([optional], a|b alternatives, (a | b), ...) or a form
    with placeholders in capitals (N, RUN_DIR)."""
    if any(s in text for s in ("[", "|", "...", "(")):
        return False
    return not any(t.isupper() and len(t) > 1 or t in ("N", "I", "S", "F", "P") for t in tokens)


SHELL_OPERATORS = {"&&", "||", ";", "|", "&"}
ASSIGNMENT = re.compile(r"^[A-Za-z_]\w*=")
REDIRECT = re.compile(r"^[<>]")


def block_commands(block: Block) -> list[tuple[str, list[str]]]:
    """(page:line, argv) of each concrete `tactile-manip ...` (or `python -m tactile_manip ...`) command of a
    bash block: comments dropped, continued lines joined, lines split at `&&`, `||`, `;`, `|` and `&`, a
    command cut at a redirection, leading VAR=value assignments dropped; synopses are left out as in prose."""
    out = []
    logical, start, pending = [], 0, ""
    for n, line in enumerate(block.code.splitlines(), block.line + 1):
        start = start if pending else n
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        logical.append((start, pending + line))
        pending = ""
    for n, line in logical:
        if not line.strip():
            continue
        lexer = shlex.shlex(line, posix=True, punctuation_chars=True)  # drops comments, splits at operators
        lexer.whitespace_split = True
        commands, command = [], []
        for token in [*lexer, ";"]:
            if token in SHELL_OPERATORS:
                commands.append(command)
                command = []
            else:
                command.append(token)
        for command in commands:
            while command and ASSIGNMENT.match(command[0]):
                command = command[1:]
            if command[:3] in (["python", "-m", "tactile_manip"], ["python3", "-m", "tactile_manip"]):
                command = ["tactile-manip", *command[3:]]
            if not command or command[0] != "tactile-manip":
                continue
            command = command[:next((i for i, tok in enumerate(command) if REDIRECT.match(tok)), len(command))]
            if not concrete(" ".join(command), command):
                continue
            out.append((f"{block.page}:{n}", command))
    return out


def exact_options(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``parser`` with its subcommands' parsers refusing abbreviated options: a page that writes `--seconds`
    for `--seconds-s` works today only until another option starts the same way."""
    parser.allow_abbrev = False
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                exact_options(sub)
    return parser


def parse_error(cmd: str | list[str], *, partial: bool = True) -> str | None:
    """The parser's complaint about ``cmd`` (a command line, or its argv): None when it parses. With
    ``partial`` a mention missing required options is fine (prose); a block's command must be whole."""
    from tactile_manip.cli import build_parser

    argv = shlex.split(cmd) if isinstance(cmd, str) else cmd
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            exact_options(build_parser()).parse_args(argv[1:])
    except SystemExit as e:
        message = err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else ""
        if e.code in (0, None) or partial and PARTIAL.search(message):
            return None
        return message or f"exit status {e.code}"
    return None


@pytest.mark.parametrize("page", PAGES)
def test_inline_commands_parse(page):
    bad = [f"{where}: `{cmd}`: {error}" for where, cmd in inline_commands(page, (ROOT / page).read_text())
           if (error := parse_error(cmd))]
    assert not bad, "inline commands the parser refuses:\n" + "\n".join(bad)


def test_inline_check_catches_a_wrong_option():
    assert parse_error("tactile-manip trials --config x.toml --trails 3") is not None
    assert parse_error("tactile-manip emulate --wire-format reskin") is not None
    assert parse_error("tactile-manip trials --resume") is None  # a partial mention
    assert inline_commands("p.md", "run `tactile-manip score RUN_DIR` or `tactile-manip params --markdown`") == [
        ("p.md:1", "tactile-manip params --markdown")]


# --- the commands of bash blocks, skipped ones included ---------------------------------------------------------
@pytest.mark.parametrize("page", PAGES)
def test_block_commands_parse(page):
    """Every concrete `tactile-manip` command of every bash block parses, whole: in a block that is skipped
    (data, hardware, minutes of CPU) this is the only check, so a renamed option fails here."""
    bad = [f"{where}: `{shlex.join(argv)}`: {error}"
           for block in blocks(page, (ROOT / page).read_text()) if block.lang == "bash"
           for where, argv in block_commands(block) if (error := parse_error(argv, partial=False))]
    assert not bad, "commands in bash blocks that the parser refuses:\n" + "\n".join(bad)


def test_block_commands_are_found_and_checked():
    code = ("<!-- doc-test: skip (needs a robot) -->\n```bash\n"
            'pip install -e ".[serial]"   # tactile-manip is installed\n'
            "tactile-manip params | head -5\n"
            "cd run && TACTILE_MANIP_POSE_KERNEL=numpy tactile-manip trials --config s.toml --trails 3 > log.txt\n"
            "tactile-manip import --readings R.npy --images I.npy [--split S.npy | --groups G.npy] --out D.npz\n"
            "tactile-manip trials --config ... --out DIR --resume\n"
            "python -m tactile_manip score run \\\n    --tolerance-deg 2.5  # at another tolerance\n"
            "tactile-manip collect run (--sim | --port P) --out d.npz\n```\n")
    block = blocks("p.md", code)[0]
    assert block.skip == "needs a robot"
    assert block_commands(block) == [
        ("p.md:4", ["tactile-manip", "params"]),
        ("p.md:5", ["tactile-manip", "trials", "--config", "s.toml", "--trails", "3"]),
        ("p.md:8", ["tactile-manip", "score", "run", "--tolerance-deg", "2.5"])]
    errors = [parse_error(argv, partial=False) for _, argv in block_commands(block)]
    assert errors[0] is None and errors[2] is None
    assert "unrecognized arguments: --trails 3" in errors[1]
    assert parse_error(["tactile-manip", "score", "--tolerance-deg", "2.5"], partial=False) is not None  # no RUN_DIR
    assert parse_error(["tactile-manip", "score", "--tolerance-deg", "2.5"]) is None  # a mention in prose
    assert "unrecognized arguments: --tolerance 2.5" in parse_error("tactile-manip score run --tolerance 2.5")


# --- quoted missing-extra messages -----------------------------------------------------------------------------
# (page, argv, the optional module hidden): the page quotes, in a plain fenced block, the line the command prints
QUOTED_ERRORS = [
    ("README.md", ["record", "--port", "/dev/ttyUSB0", "--out", "{tmp}/x.tmrec"], "serial"),
    ("docs/sensors.md", ["view", "--port", "/dev/ttyUSB0"], "serial"),
]


@pytest.mark.parametrize(("page", "argv", "module"), QUOTED_ERRORS, ids=[q[0] for q in QUOTED_ERRORS])
def test_quoted_missing_extra_lines_are_what_the_command_prints(page, argv, module, tmp_path, monkeypatch, capsys):
    from tactile_manip.cli import main

    for name in [m for m in sys.modules if m == module or m.startswith(module + ".")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, module, None)  # `import serial` raises ImportError, as when not installed
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    quoted = {b.code.strip() for b in blocks(page, (ROOT / page).read_text()) if b.lang == ""}
    assert err in quoted, f"{page} quotes no plain block with the line the command prints:\n{err}"
