"""The ``cipstack eds generate`` command: write the EDS files of the emulated devices.

``cipstack eds generate --profile PROFILE [--model M | --all] -o DIR``

Every family says how its EDS descriptions are made (``Profile.eds``, a ``module:function``
reference: the EDS tool sits above the devices, which never import it), so this command holds no
table of families of its own:

* a family of one model (the ACG): its one file (``--model`` is refused);
* a family with models (MX2, RX): the file of one model (``--model MX2-A2015-E``), or with
  ``--all`` one file per EDS file name its models declare (``Profile.model_info``: Tables 2/3
  give two models of one product code one file). One of ``--model`` and ``--all`` is required.

Files are written as bytes (ASCII, CRLF), dated by ``SOURCE_DATE_EPOCH`` when it is set, else
by the generator's fixed date; the paths written are printed one per line. Errors (an unknown
profile or model, a directory that cannot be written) are one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, TextIO

from ..errors import BadRequest, NotFound

if TYPE_CHECKING:
    from ..devices.profiles import Profile
    from .description import EdsDescription

# The generator and the descriptions (which build the devices they describe) are imported when a
# file is generated: the command line's parser takes this module's arguments for every command.

EXIT_OK = 0
EXIT_USAGE = 2


class GenerateError(BadRequest):
    """A request the command cannot carry out; the message is the one line it prints."""


def add_generate_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--profile", required=True, metavar="PROFILE",
                        help="device family (`cipstack models` lists them)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--model", metavar="M", help="model of a family with models, e.g. MX2-A2015-E")
    which.add_argument("--all", action="store_true", help="every EDS file of the family's table")
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="directory to write the files to")


def describer(profile: Profile) -> Callable[..., EdsDescription]:
    """The function ``profile.eds`` names, imported; ``GenerateError`` for a family without an EDS file or
    whose reference does not lead to a function."""
    import importlib

    if profile.eds is None:
        raise GenerateError(f"profile {profile.name} declares no EDS file")
    module_name, _, attribute = profile.eds.partition(":")
    try:
        found: object = importlib.import_module(module_name)
        for part in attribute.split("."):
            found = getattr(found, part)
    except (ImportError, AttributeError) as exc:
        raise GenerateError(f"profile {profile.name}: its EDS description {profile.eds} cannot be loaded: "
                            f"{exc}") from None
    if not callable(found):
        raise GenerateError(f"profile {profile.name}: its EDS description {profile.eds} is not a function")
    describe: Callable[..., EdsDescription] = found
    return describe


def descriptions(profile: str, model: str | None = None, every: bool = False) -> list[EdsDescription]:
    """The descriptions a command line asks for; ``GenerateError`` when it asks for none."""
    from ..devices.profiles import PROFILES

    key = profile.strip().lower()
    if key not in PROFILES:
        raise GenerateError(f"unknown profile {profile!r} (known: {', '.join(PROFILES)})")
    try:
        family = PROFILES[key]
    except NotFound as exc:   # a plug-in that cannot be loaded
        raise GenerateError(str(exc)) from None
    describe = describer(family)
    if family.find_model is None:
        if model is not None:
            raise GenerateError(f"profile {key} has one model; give no --model")
        return [describe()]
    if every:
        by_file: dict[str, str] = {}
        for item in family.model_info():
            by_file.setdefault(item.eds_file or item.name, item.name)
        return [describe(name) for name in by_file.values()]
    if model is None:
        raise GenerateError(f"profile {key}: give --model M or --all")
    try:
        found = family.find_model(model)
    except NotFound as exc:
        raise GenerateError(str(exc)) from None
    return [describe(found)]


def write_descriptions(items: list[EdsDescription], directory: str,
                       text: Callable[[EdsDescription], str] | None = None) -> list[str]:
    """Write each description's file into ``directory`` (made if missing); the paths written.
    ``text`` makes a file's text (default: the generator's ``eds_text``)."""
    from .generator import eds_text
    from .profiles import eds_file_name
    from .writer import encode_eds

    text = text or eds_text
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError as exc:
        raise GenerateError(f"cannot create directory {directory}: {exc.strerror or exc}") from None
    if not os.path.isdir(directory):
        raise GenerateError(f"{directory} is not a directory")
    paths: list[str] = []
    for description in items:
        path = os.path.join(directory, eds_file_name(description))
        data = encode_eds(text(description))
        try:
            with open(path, "wb") as handle:
                handle.write(data)
        except OSError as exc:
            raise GenerateError(f"cannot write {path}: {exc.strerror or exc}") from None
        paths.append(path)
    return paths


def run_generate(args: argparse.Namespace, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """Generate the files ``args`` ask for; 0 on success, 2 with one line on stderr otherwise."""
    stdout = stdout or sys.stdout
    stderr = stderr or sys.stderr
    try:
        items = descriptions(args.profile, args.model, args.all)
        paths = write_descriptions(items, args.output)
    except (GenerateError, ValueError) as exc:
        print(f"cipstack eds generate: {exc}", file=stderr)
        return EXIT_USAGE
    for path in paths:
        print(path, file=stdout)
    return EXIT_OK
