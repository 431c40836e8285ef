"""The docs say what is true now: every ``evopose ...`` command line in README.md and docs/*.md is one the real CLI
accepts (parsed down to its sub-command with every option converted and checked, as tests/test_compose.py parses the
compose services, never run), and the module tables of docs/architecture.md name exactly the modules of evopose/ and vision/."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
import typer
import typer.core
import typer.main

from agents.cli.main import app

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: A command in a fenced block: `evopose` or `.venv/bin/evopose` at the start of a line (after an optional `$ `).
BLOCK_COMMAND = re.compile(r"^\s*(?:\$\s+)?(?:\.venv/bin/)?evopose(?:\s|$)")
#: A command in running text: an inline code span that starts with `evopose ` or `.venv/bin/evopose `.
INLINE_COMMAND = re.compile(r"`((?:\.venv/bin/)?evopose [^`]+)`")
#: Placeholders a template may use for a value (`--fleet F`, `--out DIR`, `--rate N`).
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*$")


def block_commands(text: str) -> list[tuple[int, str]]:
    """``(line number, command)`` of every evopose command line in the fenced code blocks of ``text``: continuation
    lines joined, the trailing comment and ``&`` dropped."""
    found, fenced, pending, start = [], False, "", 0
    for number, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            continue
        if pending:
            line, pending = pending + " " + line.strip(), ""
        elif BLOCK_COMMAND.match(line):
            start = number
        else:
            continue
        code = re.split(r"\s+#\s", line, maxsplit=1)[0].rstrip()
        if code.endswith("\\"):
            pending = code[:-1].rstrip()
            continue
        found.append((start, code.rstrip("&").strip()))
    return found


def inline_commands(text: str) -> list[tuple[int, str]]:
    """``(line number, command)`` of every evopose command in an inline code span outside fenced blocks."""
    found, fenced = [], False
    for number, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
        elif not fenced:
            found += [(number, m.group(1)) for m in INLINE_COMMAND.finditer(line)]
    return found


def expand_template(command: str) -> str:
    """A command as running text writes it, made literal: ``[--opt X]`` optional parts kept, ``a|b`` the first
    alternative, ``...`` (more options) dropped."""
    command = re.sub(r"\[([^\[\]]*)\]", lambda m: m.group(1).split(" | ")[0], command)
    command = re.sub(r"(\S+)\|\S+", r"\1", command)
    return " ".join(word for word in command.split() if word != "...")


def parse(cli, argv: list[str], placeholders: bool = False):
    """Parse ``evopose ARGV`` down to its sub-command's context without invoking it: every group resolved, every
    option of the command converted and validated (unknown ones, bad values, missing required ones raise).
    ``placeholders``: a value written as a placeholder (``N``, ``DIR``) for an option that wants a number or a
    choice is accepted as the option's default."""
    assert Path(argv[0]).name == "evopose", argv
    args = list(argv[1:])
    context = cli.make_context("evopose", list(args))
    command = cli
    while isinstance(command, typer.core.TyperGroup):  # a group's own context keeps its sub-command apart: follow args
        name, command, args = command.resolve_command(context, args)
        if placeholders:
            args = [_fill(command, args, i) for i in range(len(args))]
        context = command.make_context(name, list(args), parent=context)
    return context


def _fill(command, args: list[str], i: int) -> str:
    """``args[i]``, or for a placeholder that is the value of a typed option, that option's default as text."""
    word = args[i]
    if not PLACEHOLDER.match(word) or i == 0:
        return word
    option = next((p for p in command.params if args[i - 1] in getattr(p, "opts", ())), None)
    sample = {int: "1", float: "1.0"}.get(getattr(getattr(option, "type_descriptor", None), "annotation", None))
    return word if option is None or sample is None else sample


@pytest.fixture(scope="module")
def cli():
    return typer.main.get_command(app)


def all_commands() -> list[tuple[str, int, str, bool]]:
    found = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        name = str(path.relative_to(ROOT))
        found += [(name, number, command, False) for number, command in block_commands(text)]
        found += [(name, number, command, True) for number, command in inline_commands(text)]
    return found


COMMANDS = all_commands()


def test_the_docs_have_commands_to_check():
    assert len([c for c in COMMANDS if not c[3]]) >= 40 and len([c for c in COMMANDS if c[3]]) >= 20
    assert {name for name, *_ in COMMANDS} >= {"docs/fleet.md", "docs/cameras.md", "docs/ros2.md"}


@pytest.mark.parametrize("where, number, command, inline", COMMANDS,
                         ids=[f"{c[0]}:{c[1]}" for c in COMMANDS])
def test_every_command_line_parses(cli, where, number, command, inline):
    """A command line in a code block parses whole, as the CLI would parse it (optional parts in brackets and
    ``a|b`` alternatives expanded first, placeholders such as ``S`` for a number taken as the default): every
    required option there, every value converted. One in running text names a command and some of its options
    (`evopose agent`, `evopose solve --camera`): the command must exist, each option must be one of it and each
    value given must convert."""
    argv = shlex.split(expand_template(command))
    try:
        if inline:
            mention(cli, argv)
        else:
            parse(cli, argv, placeholders=True)
    except (typer.TyperException, typer.BadParameter) as err:
        pytest.fail(f"{where}:{number}: `{command}` does not parse: {err.format_message()}")


def mention(cli, argv: list[str]) -> None:
    """Check a command mentioned in running text: the sub-command path resolves, every ``--option`` is one of the
    command's and a value given to it (not a placeholder) converts."""
    assert Path(argv[0]).name == "evopose", argv
    args, context, command = list(argv[1:]), cli.make_context("evopose", [], resilient_parsing=True), cli
    while isinstance(command, typer.core.TyperGroup) and args and not args[0].startswith("-"):
        name, command, args = command.resolve_command(context, args)
        if command is None:
            raise typer.BadParameter(f"no command {name!r} in {context.command_path}")
        context = command.make_context(name, [], parent=context, resilient_parsing=True)
    options = {}
    options.update({opt: p for p in command.params for opt in (*getattr(p, "opts", ()), *getattr(p, "secondary_opts", ()))})
    for i, word in enumerate(args):
        if not word.startswith("--"):
            continue
        for flag in word.split("="  if "=" in word else "/"):
            if not flag.startswith("--"):
                continue
            if flag == "--help":
                continue
            if flag not in options:
                raise typer.BadParameter(f"no option {flag} in evopose {context.command_path.split(' ', 1)[-1]}")
            param = options[flag]
            value = word.split("=", 1)[1] if "=" in word else (args[i + 1] if i + 1 < len(args) else None)
            if not getattr(param, "is_flag", False) and value is not None and not value.startswith("--") \
                    and not PLACEHOLDER.match(value):
                param.process_value(context, [value] if param.multiple else value)


def test_the_check_is_not_vacuous(cli):
    """Unknown flags, bad values and misspelt sub-commands are refused, also two levels down."""
    parse(cli, ["evopose", "scenario", "run", "exp2a-features", "--frames", "3", "--record", "runs"])
    for argv in (["evopose", "scenario", "run", "x", "--frames", "three"],
                 ["evopose", "scenario", "run", "x", "--bogus"],
                 ["evopose", "agent", "--vehicle", "H1"],
                 ["evopose", "scenaro", "run"],
                 ["evopose", "fleet", "credentials", "creds", "--fleet", "a", "--nope"]):
        with pytest.raises((typer.TyperException, typer.BadParameter)):
            parse(cli, argv)
    assert block_commands("```sh\n.venv/bin/evopose agent --fleet F \\\n    --vehicle H1 &  # a comment\n```\n") == [
        (2, ".venv/bin/evopose agent --fleet F --vehicle H1")]
    assert expand_template("evopose view --fleet F [--model pioneer|none] ...") == \
        "evopose view --fleet F --model pioneer"
    mention(cli, ["evopose", "solve", "--camera"])
    mention(cli, ["evopose", "scenario", "run"])
    for argv in (["evopose", "solve", "--kamera"], ["evopose", "scenario", "run", "--frames", "three"],
                 ["evopose", "scenario", "rnu"]):
        with pytest.raises((typer.TyperException, typer.BadParameter)):
            mention(cli, argv)


# -- module tables ----------------------------------------------------------------------------------------------

def module_table_rows(text: str) -> list[list[str]]:
    """The rows of every markdown table whose first header cell is ``module``: each row's ``x.py`` names."""
    rows, in_table = [], False
    for line in text.splitlines():
        if re.match(r"^\|\s*module\s*\|", line):
            in_table = True
        elif in_table and line.startswith("|"):
            if not set(line) <= set("|-: "):
                rows.append(re.findall(r"`([\w/]+\.py)`", line.split("|")[1]))
        else:
            in_table = False
    return rows


def test_module_tables_name_the_modules_that_exist_and_every_one():
    """Every module table in README.md and docs/ names only modules that exist, and the ones for evopose/ and vision/ (in
    docs/architecture.md) names every module of the package."""
    modules = {p.name for pkg in ("evopose", "vision") for p in (ROOT / pkg).glob("*.py") if p.name != "__init__.py"}
    named_in_architecture = set()
    for path in DOCS:
        for row in module_table_rows(path.read_text(encoding="utf-8")):
            assert row, f"{path.name}: a module table row names no module"
            for name in row:
                assert name in modules, f"{path.relative_to(ROOT)}: the module table names {name}, which does not exist"
            if path.name == "architecture.md":
                named_in_architecture.update(row)
    missing = sorted(modules - named_in_architecture)
    assert not missing, f"docs/architecture.md's module table misses {missing}"


def test_module_table_check_is_not_vacuous():
    rows = module_table_rows("| module | idea |\n|---|---|\n| `pose.py`, `camera.py` | x |\n\ntext | `a.py` |\n")
    assert rows == [["pose.py", "camera.py"]]
