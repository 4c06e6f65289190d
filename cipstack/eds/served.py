"""The EDS file an emulated device serves through its File object (class 0x37, instance 0xC8), as
EtherNet/IP devices that carry their EDS do: generated from the same declarations as
``cipstack eds generate`` writes, or, for a device emulated from an EDS file, that file."""

from __future__ import annotations

import functools

from ..objects.file import StoredFile, eds_file

#: The file name devices give their EDS in the File object (OpENer's File object; Rockwell 1444 Table 287).
FILE_NAME = "EDS.txt"


@functools.cache
def profile_eds_file(profile: str, model: str | None = None) -> StoredFile:
    """The EDS file of an emulated profile and model (as its ``Profile.eds`` describes it), generated when first
    read (the ACG's takes about half a second) and then kept: the devices of one profile and model
    in a process (a fleet's) share it."""
    from ..devices.profiles import PROFILES
    from .commands_generate import descriptions
    from .description import FILE_REVISION
    from .generator import eds_text
    from .writer import encode_eds

    chosen = model or PROFILES[profile].default_model

    @functools.cache
    def content() -> bytes:
        (description,) = descriptions(profile, chosen)
        return encode_eds(eds_text(description))

    return eds_file(FILE_NAME, FILE_REVISION, content)


def profile_eds_files(profile: str, model: str | None = None) -> tuple[StoredFile, ...]:
    """What a device of ``profile`` serves in its File object: its EDS file (``profile_eds_file``), or
    nothing for a family that declares none (``Profile.eds``)."""
    from ..devices.profiles import PROFILES

    return (profile_eds_file(profile, model),) if PROFILES[profile].eds is not None else ()


def document_eds_file(data: bytes, revision: tuple[int, int]) -> StoredFile:
    """The EDS file a device emulated from that file serves: the file itself, byte for byte."""
    return eds_file(FILE_NAME, revision, lambda: data)
