"""The ``cipstack eds generate`` command: write the EDS files of the emulated devices.

``cipstack eds generate --profile acg|mx2|rx [--model M | --all] -o DIR``

* ``acg``: the ACG-ET2's one file (``--model`` is refused: the profile has one model).
* ``mx2`` / ``rx``: the file of one inverter model (``--model MX2-A2015-E``), or with ``--all``
  every file of Table 2 (MX2) or Table 3 (RX), one per product code, under the names of the
  tables. One of ``--model`` and ``--all`` is required.

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

from ..devices.omron.models import Family, UnknownModelError
from ..devices.omron.models import model as omron_model
from ..errors import BadRequest

if TYPE_CHECKING:
    from .description import EdsDescription

# The generator and the descriptions (which build the devices they describe) are imported when a
# file is generated: the command line's parser takes this module's arguments for every command.

EXIT_OK = 0
EXIT_USAGE = 2

PROFILES: dict[str, Family | None] = {"acg": None, "mx2": Family.MX2, "rx": Family.RX}


class GenerateError(BadRequest):
    """A request the command cannot carry out; the message is the one line it prints."""


def add_generate_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--profile", required=True, metavar="PROFILE",
                        help="device family: " + ", ".join(PROFILES))
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--model", metavar="M", help="inverter model of Tables 2/3, e.g. MX2-A2015-E")
    which.add_argument("--all", action="store_true", help="every EDS file of the family's table")
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="directory to write the files to")


def descriptions(profile: str, model: str | None = None, every: bool = False) -> list[EdsDescription]:
    """The descriptions a command line asks for; ``GenerateError`` when it asks for none."""
    from .profiles import acg_et2_description, omron_description, omron_models_by_file

    key = profile.strip().lower()
    if key not in PROFILES:
        raise GenerateError(f"unknown profile {profile!r} (known: {', '.join(PROFILES)})")
    family = PROFILES[key]
    if family is None:
        if model is not None:
            raise GenerateError(f"profile {key} has one model; give no --model")
        return [acg_et2_description()]
    if every:
        return [omron_description(item.name) for item in omron_models_by_file(family)]
    if model is None:
        raise GenerateError(f"profile {key}: give --model M or --all")
    try:
        found = omron_model(model)
    except UnknownModelError as exc:
        raise GenerateError(str(exc)) from None
    if found.family is not family:
        raise GenerateError(f"{found.name} is an {found.family.value} model, not {family.value}")
    return [omron_description(found.name)]


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
