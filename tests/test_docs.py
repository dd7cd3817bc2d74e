"""The documentation checks: README.md, CHANGELOG.md and docs/*.md against the code.

* every relative link (and image) points at a file that exists, and every #anchor at a heading;
* every repository path named in inline code (`aicalib_tf/calib/fit.py`, `tests/data/...`) exists;
* every command in a ```bash block parses: ``python -m X ...`` with X's own parser (parsed, not
  run), ``python script.py`` names a file that exists, ``make T`` a target of the Makefile;
* no history of the work: no "session", no "issue 25" or "#34";
* docs/cli.md is what ``python -m aicalib_tf.docs`` writes now;
* the README stays short (≤ 12 KB) with the calibrate command on its first screen.
"""

from __future__ import annotations

import contextlib
import glob
import io
import re
import shlex
from pathlib import Path

import pytest

from aicalib_tf import docs as docs_module

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]
README_MAX_BYTES = 12 * 1024
DOCS_PAGE_MAX_BYTES = 40 * 1024  # every docs/*.md page but the generated cli.md
# headings that narrate the work instead of naming what the page describes
JOURNAL_HEADING = re.compile(r"^(before|after|now|what changed|what is left|tried)\b|\b\d{4}-\d{2}-\d{2}\b", re.IGNORECASE)
FIRST_SCREEN_LINES = 40

# where a path in inline code must start to be taken as a path into this repository
TOP_LEVEL = ("aicalib_tf/", "data_gen/", "docs/", "tests/", "benchmarks/", "models/", "notebooks/", ".ci/")
SUBPACKAGES = {p.name for p in (ROOT / "aicalib_tf").iterdir() if (p / "__init__.py").exists()}
PATH_SUFFIXES = (".py", ".md", ".ipynb", ".png", ".json", ".yaml", ".yml", ".toml", ".csv", ".txt", ".html",
                 ".keras", ".tflite", ".sha256", ".jpg")
EXTERNAL_MODULES = ("pytest", "pip", "venv")  # python -m modules that are not ours
HISTORY = [
    (re.compile(r"\bsessions?\b(?!\.py)", re.IGNORECASE), "names a work session"),
    (re.compile(r"\bissues?[\s-]*#?\d+", re.IGNORECASE), "names an issue number"),
    (re.compile(r"(?<![\w&/`])#\d+\b"), "names an issue or PR number"),
]

FENCE = re.compile(r"^```([\w-]*)\s*$")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
CODE_SPAN = re.compile(r"`([^`\n]+)`")


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def _split(text: str) -> tuple[list[tuple[int, str]], list[tuple[str, int, list[str]]]]:
    """(prose lines with their numbers, fenced blocks as (language, first line number, lines))."""
    prose, blocks, block = [], [], None
    for number, line in enumerate(text.split("\n"), 1):
        m = FENCE.match(line.strip())
        if block is None and m:
            block = (m.group(1), number + 1, [])
        elif block is not None and line.strip() == "```":
            blocks.append(block)
            block = None
        elif block is not None:
            block[2].append(line)
        else:
            prose.append((number, line))
    return prose, blocks


def _anchors(path: Path) -> set[str]:
    """GitHub's anchors of a page's headings."""
    found, seen = set(), {}
    prose, _ = _split(path.read_text(encoding="utf-8"))
    for _, line in prose:
        m = re.match(r"^#{1,6}\s+(.*?)\s*$", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).replace("`", "").lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        found.add(slug if n == 0 else f"{slug}-{n}")
    return found


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_links_resolve(page):
    prose, _ = _split(page.read_text(encoding="utf-8"))
    broken = []
    for number, line in prose:
        for target in LINK.findall(line):
            if re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            dest = (page.parent / file_part).resolve() if file_part else page
            if not dest.exists():
                broken.append(f"line {number}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                broken.append(f"line {number}: {target} (no heading with that anchor)")
    assert not broken, f"{_rel(page)}: broken links:\n" + "\n".join(broken)


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_repository_paths_exist(page):
    prose, _ = _split(page.read_text(encoding="utf-8"))
    missing = []
    for number, line in prose:
        for span in CODE_SPAN.findall(line):
            path = span.split()[0].removesuffix("'s").rstrip(".,;:)") if span.split() else ""
            if path.split("/")[0] in SUBPACKAGES and path.endswith(".py"):
                path = "aicalib_tf/" + path  # `calib/bundle.py`, as the package's own pages write it
            if not path.startswith(TOP_LEVEL) or not re.fullmatch(r"[\w.\-/*]+", path):
                continue
            if not (path.endswith("/") or path.endswith(PATH_SUFFIXES) or "." not in Path(path).name):
                continue  # a file type this check does not know (a built extension, say)
            if not glob.glob(str(ROOT / path)):
                missing.append(f"line {number}: {span}")
    assert not missing, f"{_rel(page)}: paths that do not exist in the repository:\n" + "\n".join(missing)


def _commands(page: Path) -> list[tuple[int, str]]:
    """The logical lines of a page's ```bash blocks (backslash continuations joined)."""
    _, blocks = _split(page.read_text(encoding="utf-8"))
    out = []
    for language, first, lines in blocks:
        if language not in ("bash", "sh", "shell"):
            continue
        pending, start = "", None
        for offset, line in enumerate(lines):
            if start is None:
                start = first + offset
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            text = (pending + line).strip()
            pending, number, start = "", start, None
            if text and not text.startswith("#"):
                out.append((number, text))
    return out


def _makefile_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    return set(re.findall(r"^([\w.-]+):", text, re.MULTILINE))


def _check_command(text: str) -> str | None:
    """None if the command is well formed, else why not."""
    tokens = shlex.split(text, comments=True)
    while tokens and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*=.*", tokens[0]):  # VAR=value prefixes
        tokens.pop(0)
    if not tokens:
        return None
    program = tokens[0].removeprefix(".venv/bin/")
    if program == "make":
        unknown = [t for t in tokens[1:] if not t.startswith("-") and "=" not in t and t not in _makefile_targets()]
        return f"no Makefile target {unknown}" if unknown else None
    if program not in ("python", "python3") or len(tokens) < 2:
        return None  # another tool (pip, cp, ...): not ours to check
    if tokens[1] != "-m":
        script = ROOT / tokens[1]
        return None if script.exists() else f"no script {tokens[1]}"
    module, args = tokens[2], tokens[3:]
    if module in EXTERNAL_MODULES:
        return None
    try:
        parser = docs_module.build_parser_for(module)
    except ValueError as exc:
        return str(exc)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            parser.parse_args(args)
    except SystemExit:
        return f"{module} does not accept these arguments: {err.getvalue().strip().splitlines()[-1]}"
    return None


@pytest.mark.parametrize("page", [p for p in PAGES if p.name != "cli.md"], ids=_rel)
def test_bash_commands_parse(page):
    bad = [f"line {n}: {text}\n  -> {why}" for n, text in _commands(page) if (why := _check_command(text))]
    assert not bad, f"{_rel(page)}: commands that would not run:\n" + "\n".join(bad)


def test_readme_quick_start_has_commands():
    commands = [text for _, text in _commands(ROOT / "README.md")]
    assert any(c.startswith("make demo") for c in commands) and any(c.startswith("make test") for c in commands)
    assert any("aicalib_tf.calibrate" in c for c in commands)


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_no_history_wording(page):
    found = []
    for number, line in enumerate(page.read_text(encoding="utf-8").split("\n"), 1):
        for pattern, why in HISTORY:
            for m in pattern.finditer(line):
                found.append(f"line {number}: {why}: ...{line[max(0, m.start() - 30): m.end() + 30]}...")
    assert not found, f"{_rel(page)} speaks of the history of the work, not the software:\n" + "\n".join(found)


@pytest.mark.parametrize("page", [p for p in PAGES if p.parent.name == "docs" and p.name != "cli.md"], ids=_rel)
def test_docs_page_is_a_short_reference(page):
    size = page.stat().st_size
    assert size <= DOCS_PAGE_MAX_BYTES, f"{_rel(page)} is {size} bytes (at most {DOCS_PAGE_MAX_BYTES}): condense it"
    prose, _ = _split(page.read_text(encoding="utf-8"))
    journal = [f"line {n}: {line}" for n, line in prose
               if (m := re.match(r"^#{1,6}\s+(.*)$", line)) and JOURNAL_HEADING.search(m.group(1))]
    assert not journal, f"{_rel(page)}: headings that narrate the work:\n" + "\n".join(journal)


def test_cli_reference_is_up_to_date():
    current = docs_module.CLI_DOC.read_text(encoding="utf-8")
    assert current == docs_module.render(), "docs/cli.md is out of date: run python -m aicalib_tf.docs"


def test_docs_check_exit_codes(tmp_path):
    out = tmp_path / "cli.md"
    assert docs_module.main(["--check", "--out", str(out)]) == 1  # missing
    assert docs_module.main(["--out", str(out)]) == 0
    assert docs_module.main(["--check", "--out", str(out)]) == 0
    out.write_text(out.read_text(encoding="utf-8") + "edited by hand\n", encoding="utf-8")
    assert docs_module.main(["--check", "--out", str(out)]) == 1


def test_every_entry_point_builds_its_parser_without_parsing():
    for command, module, _ in docs_module.ENTRY_POINTS:
        parser = docs_module.build_parser_for(command)
        assert parser.prog == command, (module, parser.prog)


def test_readme_is_short_with_calibrate_on_the_first_screen():
    readme = ROOT / "README.md"
    assert readme.stat().st_size <= README_MAX_BYTES, f"README.md is {readme.stat().st_size} bytes"
    first_screen = readme.read_text(encoding="utf-8").split("\n")[:FIRST_SCREEN_LINES]
    assert any("python -m aicalib_tf.calibrate" in line for line in first_screen)
