"""The command line explains itself: every command's description and examples (which parse), the
defaults its help names, the list of commands, the usage with a parser error, a closed stdout, and
shell completion."""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from cipstack.capture.synth import PcapWriter, TcpFlow, ethernet
from cipstack.cip.epath import request_path
from cipstack.cip.messages import MessageRouterRequest, Service
from cipstack.cli.help_texts import COMMANDS
from cipstack.cli.io import PRINT_MODES, parse_print
from cipstack.cli.parser import arguments, build_parser, command_word, subcommands
from cipstack.eip.wire.cpf import Item, ItemType, encode_items
from cipstack.eip.wire.encapsulation import RR_PREFIX, Command, encode_frame
from tests.optional import needs

#: What ends the command part of an example (a pipe, a redirection).
SHELL_OPERATORS = {"|", ">", ">>", "<", ";", "&&", "||"}


def run(*args: str, **kwargs: object) -> subprocess.CompletedProcess[str]:
    options: dict[str, object] = {"capture_output": True, "text": True, "timeout": 60, "stdin": subprocess.DEVNULL}
    options.update(kwargs)
    return subprocess.run([sys.executable, "-m", "cipstack", *args], **options)  # type: ignore[call-overload]


def commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> Iterator[
        tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every command's parser, by its path (``("drive", "trip")``), nested ones included."""
    for name, sub in subcommands(parser).items():
        yield (*path, name), sub
        yield from commands(sub, (*path, name))


def test_every_command_has_a_description_and_examples_that_parse() -> None:
    found = list(commands(build_parser(None)))
    assert {path[0] for path, _ in found} >= {"adapter", "fleet", "models", "componet", "discover", "identity",
                                              "get", "set", "io", "drive", "eds", "capture", "completion",
                                              "params"}
    for path, parser in found:
        assert parser.description and len(parser.description.split()) >= 8, path
        examples = [line.strip() for line in (parser.epilog or "").splitlines() if line.startswith("  cipstack ")]
        own = 0
        for example in examples:
            words = shlex.split(example)[1:]
            cut = next((i for i, word in enumerate(words) if word in SHELL_OPERATORS), len(words))
            words = words[:cut]
            own += words[:len(path)] == list(path)
            args = build_parser(command_word(words)).parse_args(words)   # a bad one raises UsageError
            assert args.command == words[0], example
        assert own, f"{' '.join(path)} has no example of its own"


def test_cipstack_alone_lists_every_command_with_its_line_and_exits_2() -> None:
    result = run()
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and result.stdout == ""
    listed = dict(re.findall(r"^    (\w+) +(\S.*)$", result.stderr, re.MULTILINE))
    expected = {name: COMMANDS[(name,)].help for name in subcommands(build_parser(None))}
    assert set(listed) == set(expected)
    for name, line in listed.items():
        assert expected[name].startswith(line), name
    assert result.stderr.rstrip().splitlines()[-1] == "cipstack: error: the following arguments are required: COMMAND"


def test_a_group_s_line_names_every_subcommand_it_lists() -> None:
    """`cipstack --help` lists a group as "EDS files: generate, check, show, fetch": the words after its
    colon are its subcommands, all of them (`fetch` was left out); and `cipstack eds --help` names
    each of its subcommands, in its description and in its list of commands."""
    overview = run("--help")
    assert overview.returncode == 0
    lines = dict(re.findall(r"^    ([\w-]+) +(\S.*(?:\n {24}\S.*)*)$", overview.stdout, re.MULTILINE))
    listing = 0
    for path, parser in commands(build_parser(None)):
        subcommands = [name for sub_path, _ in commands(parser) for name in sub_path[:1]]
        if len(path) != 1 or not subcommands:
            continue
        line = " ".join(lines[path[0]].split())
        listed = re.split(r",\s*", re.sub(r"\s*\(.*\)$", "", line.split(":", 1)[-1].strip()))
        if ":" in line and all(re.fullmatch(r"[\w-]+", word) for word in listed):   # a list, not prose
            assert sorted(listed) == sorted(subcommands), (path, line)
            listing += 1
    assert listing >= 2   # eds and params
    eds = run("eds", "--help")
    description = " ".join(eds.stdout.split("options:")[0].split())
    for name in ("generate", "check", "show", "fetch"):
        assert re.search(rf"^    {name} ", eds.stdout, re.MULTILINE), name
    assert "fetch the one a device carries" in description, description


@pytest.mark.parametrize(("argv", "prog", "message"), [
    (["set", "127.0.0.1", "0xF5/1/13"], "cipstack set", "the following arguments are required: VALUE"),
    (["drive"], "cipstack drive", "the following arguments are required: COMMAND"),
    (["adapter", "--port", "x"], "cipstack adapter", "port: 'x' is not a number (decimal or 0x hex)"),
    (["eds", "generate", "--profile", "acg"], "cipstack eds generate",
     "the following arguments are required: -o/--output"),
])
def test_a_parser_error_shows_the_command_s_usage_and_names_the_command(argv: list[str], prog: str,
                                                                       message: str) -> None:
    result = run(*argv)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    lines = result.stderr.rstrip().splitlines()
    assert lines[0].startswith(f"usage: {prog} ")
    assert lines[-1] == f"{prog}: error: {message}"


def test_a_default_the_help_names_is_the_parser_s_own() -> None:
    """Every option with a default shows it through ``%(default)s``; `discover` waits 2 s, not 5."""
    for path, parser in commands(build_parser(None)):
        for action in arguments(parser):
            # --help and --version (default SUPPRESS) and the choice of command (default None) go here too.
            if action.help in (None, argparse.SUPPRESS) or action.default in (None, False, [], argparse.SUPPRESS):
                continue
            assert "%(default)s" in action.help, (path, action.option_strings)
    shown = run("discover", "--help").stdout
    assert "(default 2.0 s)" in " ".join(shown.split())
    assert build_parser("discover").parse_args(["discover"]).timeout == 2.0


def test_the_print_modes_the_help_offers_are_the_ones_accepted() -> None:
    parser = build_parser("io")
    io = dict(commands(parser))[("io",)]
    action = next(a for a in arguments(io) if "--print" in a.option_strings)
    text = action.help % {"default": action.default}
    assert action.metavar == "|".join(PRINT_MODES)
    for mode in PRINT_MODES:
        assert f"{mode}: " in text
        assert parse_print(mode.replace("DURATION", "1s"))[0] == mode.split(":")[0]
    assert "none" not in text  # the word the help once offered and the parser refused
    with pytest.raises(Exception, match="not one of changes, summary, every:DURATION"):
        parse_print("none")
    assert parse_print(action.default) == ("changes", 0.0)


@pytest.fixture
def capture_file(tmp_path: Path) -> Path:
    """A capture of a few hundred explicit requests: more summary than one line."""
    path = tmp_path / "many.pcap"
    flow = TcpFlow(("10.0.0.1", 50000), ("10.0.0.2", 44818))
    with path.open("wb") as stream:
        pcap = PcapWriter(stream)
        for n in range(300):
            request = MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(0x01, 1, 7)).encode()
            items = encode_items([Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA, request)])
            frame = encode_frame(Command.SEND_RR_DATA, RR_PREFIX.pack(0, 0) + items, session=7)
            pcap.write(1.0 + n * 0.01, ethernet(flow.send(True, frame)))
    return path


@pytest.mark.parametrize("argv", [["capture", "analyze", "{file}", "--json", "--no-progress"], ["models"],
                                  ["completion", "bash"]])
def test_a_closed_stdout_ends_the_command_quietly_with_141(argv: list[str], capture_file: Path) -> None:
    """``cipstack ... | head`` once the reader is gone: no "Broken pipe", no traceback, status
    141 (128 + SIGPIPE) as ``cat`` and ``grep`` end."""
    if argv[0] == "completion":
        needs("shtab")
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line is written
    try:
        result = run(*(word.replace("{file}", str(capture_file)) for word in argv), stdout=write_end,
                     capture_output=False, stderr=subprocess.PIPE)
    finally:
        os.close(write_end)
    assert result.stderr == ""
    assert result.returncode == 141


def test_the_capture_file_of_the_pipe_test_has_output(capture_file: Path) -> None:
    result = run("capture", "analyze", str(capture_file), "--json", "--no-progress")
    assert result.returncode == 0, result.stderr
    assert len(result.stdout.splitlines()) > 1


def test_bash_completion_is_generated_and_bash_accepts_it(tmp_path: Path) -> None:
    needs("shtab")
    result = run("completion", "bash")
    assert result.returncode == 0, result.stderr
    script = tmp_path / "cipstack.bash"
    script.write_text(result.stdout)
    assert "capture" in result.stdout and "--list-fields" in result.stdout and "--against" in result.stdout
    checked = subprocess.run(["bash", "-n", str(script)], capture_output=True, text=True, timeout=30)
    assert checked.returncode == 0, checked.stderr
    # Loaded into a shell, it completes the commands.
    probe = (f"source {shlex.quote(str(script))}; COMP_WORDS=(cipstack ca); COMP_CWORD=1; "
             "COMP_LINE='cipstack ca'; COMP_POINT=${#COMP_LINE}; "
             "$(complete -p cipstack | sed -E 's/.*-F ([^ ]+).*/\\1/') cipstack ca cipstack; "
             "printf '%s\\n' \"${COMPREPLY[@]}\"")
    completed = subprocess.run(["bash", "-c", probe], capture_output=True, text=True, timeout=30)
    assert completed.stdout.split() == ["capture"], completed.stderr


@pytest.mark.skipif(shutil.which("zsh") is None, reason="zsh is not installed")
def test_zsh_completion_is_generated_and_zsh_accepts_it(tmp_path: Path) -> None:
    needs("shtab")
    result = run("completion", "zsh")
    assert result.returncode == 0, result.stderr
    script = tmp_path / "_cipstack"
    script.write_text(result.stdout)
    checked = subprocess.run(["zsh", "-n", str(script)], capture_output=True, text=True, timeout=30)
    assert checked.returncode == 0, checked.stderr


def test_completion_without_shtab_names_the_extra() -> None:
    code = ("import sys; sys.modules['shtab'] = None\n"
            "from cipstack.cli import main\nraise SystemExit(main(['completion', 'bash']))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.strip() == ('cipstack completion: shell completion needs shtab: '
                                     'pip install "cipstack[completion]"')
