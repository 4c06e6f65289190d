"""A one-shot command's plain line is read without argparse (``cli/oneshot.py``): into the namespace
argparse gives for it, from tables that are the argparse grammar's; any other line is argparse's."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from cipstack.cli import oneshot
from cipstack.cli.parser import arguments, build_parser, command_word, subcommands


def command_parser(name: str) -> argparse.ArgumentParser:
    return subcommands(build_parser(name))[name]


@pytest.mark.parametrize("name", sorted(oneshot.COMMANDS))
def test_the_tables_are_the_argparse_grammar(name: str) -> None:
    grammar = oneshot.COMMANDS[name]
    parser = command_parser(name)
    positionals = [a.dest for a in arguments(parser) if not a.option_strings]
    options = {a.option_strings[0]: a for a in arguments(parser) if a.option_strings
               and a.dest not in ("help", "log_level")}
    assert positionals == list(grammar.positionals)
    assert {o for o, a in options.items() if a.nargs == 0} == set(grammar.flags)
    assert {o for o, a in options.items() if a.nargs != 0} == set(grammar.valued)
    for option, action in options.items():
        assert action.option_strings == [option]  # no short form the table would miss
        dest = grammar.flags.get(option) or grammar.valued[option][0]
        assert (action.dest, action.default) == (dest, grammar.defaults[dest]), option
    assert parser.get_default("log_level") is argparse.SUPPRESS
    top = build_parser(name)
    log_level = next(a for a in arguments(top) if "--log-level" in a.option_strings)
    assert (top.get_default("log_level"), tuple(log_level.choices or ())) == \
           (oneshot.DEFAULT_LOG_LEVEL, oneshot.LOG_LEVELS)


LINES = [
    ["get", "127.0.0.1", "1/1/7"],
    ["get", "127.0.0.1:44818", "0x2A/1/102", "--json"],
    ["get", "--json", "10.0.0.5", "--timeout", "500ms", "1/1", "--connected"],
    ["--log-level", "debug", "get", "h", "1/1/7", "--type", "UINT", "--route", "1/0,2/3", "--eds", "x.eds"],
    ["get", "h", "ACC", "--log-level", "warning", "--timeout", "2", "--timeout", "1.5s"],
    ["set", "127.0.0.1", "0x2A/1/102", "50"],
    ["set", "h", "0x2A/1/102", "5.0", "--scaled", "--json", "--connected", "--type", "UINT", "--route", "1/0"],
    ["--log-level", "ERROR", "set", "h", "ACC", "2.5", "--eds", "f.eds", "--timeout", "3"],
    ["identity", "127.0.0.1"],
    ["identity", "--json", "127.0.0.2:44818", "--timeout", "250ms", "--log-level", "INFO"],
    ["get", "", "1/1/7"],
    ["get", "10.0.0.5", "1/1/7", "--security", "lab"],
    ["set", "10.0.0.5:2221", "ACC", "2.5", "--security", "/etc/cipstack/lab", "--json"],
    ["identity", "--security", "lab", "10.0.0.5"],
]


@pytest.mark.parametrize("words", LINES, ids=" ".join)
def test_a_plain_line_reads_as_argparse_reads_it(words: list[str]) -> None:
    read = oneshot.parse(words)
    assert read is not None
    assert vars(read) == vars(build_parser(command_word(words)).parse_args(words))


FALLBACK = [
    [], ["--version"], ["--help"], ["get", "-h"], ["set", "--help"], ["identity"],
    ["get", "h"], ["get", "h", "1/1/7", "extra"], ["set", "h", "1/1/1"],
    ["get", "h", "1/1/7", "--time", "2"],            # an abbreviation argparse accepts
    ["get", "h", "1/1/7", "--timeout=2"],            # the = form
    ["get", "h", "1/1/7", "--timeout", "soon"],      # a bad value: argparse's usage and message
    ["get", "h", "1/1/7", "--timeout"],
    ["get", "h", "1/1/7", "--type", "--json"],
    ["--log-level", "LOUD", "get", "h", "1/1/7"],
    ["get", "h", "1/1/7", "--log-level", "LOUD"],
    ["set", "h", "1/1/1", "-5"],                     # a negative number
    ["get", "h", "1/1/7", "--"],
    ["get", "h", "1/1/7", "--scaled"],               # set's option on get
    ["identity", "h", "--type", "UINT"],
    ["get", "h", "1/1/7", "--security"],             # a folder missing: argparse's usage and message
    ["discover"], ["io", "h"], ["adapter"],          # other commands
]


@pytest.mark.parametrize("words", FALLBACK, ids=lambda w: " ".join(w) or "(none)")
def test_any_other_line_is_left_to_argparse(words: list[str]) -> None:
    assert oneshot.parse(words) is None


def test_a_one_shot_line_imports_no_argparse() -> None:
    script = ("import sys\nfrom cipstack.cli import oneshot\nargs = oneshot.parse(sys.argv[1:])\n"
              "print(args.command, args.func.__name__, 'argparse' in sys.modules,\n"
              "      'cipstack.cli.parser' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", script, "get", "h", "1/1/7", "--json"], capture_output=True,
                         text=True, check=True, timeout=60).stdout.split()
    assert out == ["get", "cmd_get", "False", "False"]
