"""File object (class 0x37): files a device serves over CIP, read with Initiate_Upload and
Upload_Transfer. An EtherNet/IP device that carries its EDS file serves it at instance 0xC8, "EDS and
Icon Files", file "EDS.txt", read-only, binary (OpENer's File object; Rockwell's 1444 manual,
Tables 285-287). Layouts as Wireshark's packet-cip.c (dissect_file_*) reads them:

* Initiate_Upload (0x4B): request maximum transfer size (USINT); reply file size (UDINT) and the
  transfer size chosen (USINT, at most the one asked for).
* Upload_Transfer (0x4F): request transfer number (USINT, from 0, wrapping at 256); reply the
  number echoed, the packet type (0 first, 1 middle, 2 last, 4 first and last), the file bytes, and
  on a last packet the file checksum (UINT): the two's complement of the 16-bit sum of the bytes.
* Initiate_Download (0x4C), on an instance made writable (``FileObject.writable``): request file
  size (UDINT), instance format version (UINT), file revision (USINT, USINT), file name (STRINGI);
  reply incremental burn (UDINT), incremental burn time (UINT), transfer size (USINT).
* Download_Transfer (0x50): request transfer number (USINT), packet type, the data, and on a last
  packet the checksum (UINT); reply the transfer number. A download to a read-only instance (the
  EDS file's), a packet out of turn or a wrong packet type is 0x0C or 0x20; a wrong checksum 0xD0.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable
from dataclasses import dataclass, field

from ..cip.epath import ApplicationPath
from ..cip.messages import MessageRouterRequest, Service
from ..cip.model import AttributeSpec, Binding, CipObject, ClassSpec, Instance
from ..cip.router import RequestContext
from ..cip.status import CipError, GeneralStatus
from ..cip.types import BYTE, REVISION, UDINT, UINT, USINT, RemainingBytes
from ..errors import ProtocolError

CLASS_ID = 0x37
#: The instance that holds the device's EDS file.
EDS_INSTANCE = 0xC8
INITIATE_UPLOAD, UPLOAD_TRANSFER = 0x4B, 0x4F
INITIATE_DOWNLOAD, DOWNLOAD_TRANSFER = 0x4C, 0x50
FIRST, MIDDLE, LAST, ABORT, FIRST_AND_LAST = 0, 1, 2, 3, 4
#: Instance attribute 1.
FILE_EMPTY, FILE_LOADED, UPLOAD_INITIATED, UPLOAD_IN_PROGRESS = 1, 2, 3, 5
DOWNLOAD_INITIATED, DOWNLOAD_IN_PROGRESS = 4, 6
#: Largest file a download takes (a certificate, a CSR: a few KB at most).
MAX_DOWNLOAD = 16384
#: Transfer size this object chooses for a download.
DOWNLOAD_TRANSFER_SIZE = 200
#: Checksum mismatch on a download (object-specific general status, as the File object's table gives).
CHECKSUM_MISMATCH = 0xD0
#: The largest transfer this object chooses (OpENer's File object caps it at 100; the request's USINT at 255).
MAX_TRANSFER = 255

STRINGI = RemainingBytes("STRINGI")

SPEC = ClassSpec(
    CLASS_ID, "File", revision=3,
    instance_attributes=(
        AttributeSpec(1, "State", USINT, default=FILE_LOADED),
        AttributeSpec(2, "Instance Name", STRINGI),
        AttributeSpec(3, "Instance Format Version", UINT, default=1),
        AttributeSpec(4, "File Name", STRINGI),
        AttributeSpec(5, "File Revision", REVISION),
        AttributeSpec(6, "File Size", UDINT),
        AttributeSpec(7, "File Checksum", UINT),
        AttributeSpec(8, "Invocation Method", USINT, default=255),
        AttributeSpec(9, "File Save Parameters", BYTE, default=0),
        AttributeSpec(10, "File Access Rule", USINT, default=1),
        AttributeSpec(11, "File Encoding Format", USINT, default=0),
    ),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=frozenset({Service.GET_ATTRIBUTE_SINGLE, INITIATE_UPLOAD, UPLOAD_TRANSFER, INITIATE_DOWNLOAD,
                                 DOWNLOAD_TRANSFER}),
    max_instance=EDS_INSTANCE,
)


def stringi(text: str) -> bytes:
    """A STRINGI of one English ISO 8859-1 SHORT_STRING: count, "eng", type 0xDA, charset 4, the string."""
    raw = text.encode("latin-1")
    return bytes((1,)) + b"eng" + bytes((0xDA,)) + struct.pack("<H", 4) + bytes((len(raw),)) + raw


def checksum(data: bytes) -> int:
    """The File object checksum: added to the 16-bit sum of every byte, it makes 0."""
    return (0x10000 - sum(data)) & 0xFFFF


@dataclass(frozen=True)
class StoredFile:
    """A file a device serves: where, under which names, and its bytes (made when first read, so that
    a device whose EDS file is generated pays for it only when someone asks)."""

    instance: int
    instance_name: str
    file_name: str
    revision: tuple[int, int]
    content: Callable[[], bytes]
    encoding: int = 0


def eds_file(file_name: str, revision: tuple[int, int], content: Callable[[], bytes]) -> StoredFile:
    """The device's EDS file, at the instance and under the names devices that carry one use."""
    return StoredFile(EDS_INSTANCE, "EDS and Icon Files", file_name, revision, content)


@dataclass
class _Upload:
    """One file's upload in progress: the transfer size chosen and the next packet expected."""

    size: int
    next_packet: int = 0
    last_sent: int = -1
    data: bytes = field(default=b"", repr=False)
    #: A download's announced file size.
    size_expected: int = 0


#: What a writable instance calls once a download is whole: its bytes and the request that ended it
#: (a ``CipError`` it raises refuses the last transfer, and the file stays as it was).
Written = Callable[[bytes, RequestContext], None]


class FileObject(CipObject):
    extra_services = {INITIATE_UPLOAD: "initiate_upload", UPLOAD_TRANSFER: "upload_transfer",
                      INITIATE_DOWNLOAD: "initiate_download", DOWNLOAD_TRANSFER: "download_transfer"}

    def __init__(self, files: tuple[StoredFile, ...]) -> None:
        super().__init__(SPEC)
        self._files: dict[int, StoredFile] = {}
        self._cache: dict[int, bytes] = {}
        self._uploads: dict[int, _Upload] = {}
        #: Writable instances: what each calls once a download is whole; downloads in progress.
        self._written: dict[int, Written] = {}
        self._downloads: dict[int, _Upload] = {}
        #: Instances whose content is read from its source at each use (never cached).
        self._live: set[int] = set()
        for stored in files:
            self.serve(stored)

    def serve(self, stored: StoredFile, written: Written | None = None, live: bool = False) -> None:
        """Serve ``stored`` at its instance; with ``written``, it can be downloaded too (read/write);
        ``live``: its content changes, and is read from ``stored.content`` at each use (``written``
        then puts what was downloaded where that reads it)."""
        self._files[stored.instance] = stored
        self._cache.pop(stored.instance, None)
        if live:
            self._live.add(stored.instance)
        instance = self.instances.get(stored.instance)
        if instance is None:
            self.add_instance(stored.instance, instance_name=stringi(stored.instance_name),
                              file_name=stringi(stored.file_name),
                              file_revision={"major": stored.revision[0], "minor": stored.revision[1]},
                              file_size=Binding(functools.partial(self._size, stored.instance)),
                              file_checksum=Binding(functools.partial(self._checksum, stored.instance)),
                              file_encoding_format=stored.encoding, file_access_rule=0 if written else 1)
        else:
            instance.values[1] = FILE_LOADED
        if written is not None:
            self._written[stored.instance] = written

    def initiate_download(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                          context: RequestContext) -> bytes:
        assert instance is not None
        state = instance.values[1]
        if instance.instance_id not in self._written:
            raise CipError(GeneralStatus.OBJECT_STATE_CONFLICT, data=bytes((state,)),
                           message="this file is read-only")
        if len(request.data) < 8:
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="Initiate_Download: size, version, revision, name")
        size = struct.unpack_from("<I", request.data)[0]
        if size > MAX_DOWNLOAD:
            raise CipError(GeneralStatus.INVALID_PARAMETER, (0x0004,), message=f"a file of {size} bytes")
        self._downloads[instance.instance_id] = _Upload(DOWNLOAD_TRANSFER_SIZE, data=b"", size_expected=size)
        instance.values[1] = DOWNLOAD_INITIATED
        return struct.pack("<IHB", 0, 0, DOWNLOAD_TRANSFER_SIZE)

    def download_transfer(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                          context: RequestContext) -> bytes:
        assert instance is not None
        download = self._downloads.get(instance.instance_id)
        if download is None:
            raise CipError(GeneralStatus.OBJECT_STATE_CONFLICT, data=bytes((instance.values[1],)),
                           message="Download_Transfer before Initiate_Download")
        if len(request.data) < 2:
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="Download_Transfer: number and packet type")
        number, kind = request.data[0], request.data[1]
        if number != download.next_packet & 0xFF:
            raise CipError(GeneralStatus.INVALID_PARAMETER, (0x0006,),
                           message=f"transfer number {number}, {download.next_packet & 0xFF} expected")
        first = download.next_packet == 0
        if kind == ABORT:
            del self._downloads[instance.instance_id]
            instance.values[1] = FILE_LOADED
            return bytes((number,))
        if kind not in ((FIRST, FIRST_AND_LAST) if first else (MIDDLE, LAST)):
            raise CipError(GeneralStatus.OBJECT_STATE_CONFLICT, data=bytes((instance.values[1],)),
                           message=f"packet type {kind} out of turn")
        chunk = request.data[2:]
        if kind in (LAST, FIRST_AND_LAST):
            if len(chunk) < 2:
                raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="the last packet has no checksum")
            data = download.data + chunk[:-2]
            (sent,) = struct.unpack_from("<H", chunk, len(chunk) - 2)
            if len(data) != download.size_expected:
                raise CipError(GeneralStatus.INVALID_PARAMETER, (0x0004,),
                               message=f"{len(data)} bytes, {download.size_expected} announced")
            if sent != checksum(data):
                del self._downloads[instance.instance_id]
                instance.values[1] = FILE_LOADED
                raise CipError(CHECKSUM_MISMATCH, message="checksum does not match the bytes")
            self._written[instance.instance_id](data, context)   # may refuse: the file stays as it was
            del self._downloads[instance.instance_id]
            if instance.instance_id not in self._live:
                stored = self._files[instance.instance_id]
                self._files[instance.instance_id] = StoredFile(stored.instance, stored.instance_name,
                                                               stored.file_name, stored.revision,
                                                               functools.partial(bytes, data), stored.encoding)
                self._cache[instance.instance_id] = data
            instance.values[1] = FILE_LOADED
            return bytes((number,))
        if len(download.data) + len(chunk) > MAX_DOWNLOAD:
            raise CipError(GeneralStatus.INVALID_PARAMETER, (0x0004,), message="more bytes than announced")
        download.data += chunk
        download.next_packet += 1
        instance.values[1] = DOWNLOAD_IN_PROGRESS
        return bytes((number,))

    def _size(self, instance: int) -> int:
        return len(self.content(instance))

    def _checksum(self, instance: int) -> int:
        return checksum(self.content(instance))

    def content(self, instance: int) -> bytes:
        if instance in self._live:
            return bytes(self._files[instance].content())
        if instance not in self._cache:
            self._cache[instance] = bytes(self._files[instance].content())
        return self._cache[instance]

    def initiate_upload(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                        context: RequestContext) -> bytes:
        assert instance is not None
        if len(request.data) < 1:
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="Initiate_Upload needs a maximum transfer size")
        if len(request.data) > 1:
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="Initiate_Upload takes one byte")
        asked = request.data[0]
        if asked == 0:
            raise CipError(GeneralStatus.INVALID_PARAMETER, message="a transfer size of 0")
        data = self.content(instance.instance_id)
        # A new Initiate_Upload restarts an upload left unfinished (a client that gave up and retries).
        upload = _Upload(min(asked, MAX_TRANSFER), data=data)
        self._uploads[instance.instance_id] = upload
        instance.values[1] = UPLOAD_INITIATED
        return struct.pack("<IB", len(data), upload.size)

    def upload_transfer(self, instance: Instance | None, path: ApplicationPath, request: MessageRouterRequest,
                        context: RequestContext) -> bytes:
        assert instance is not None
        upload = self._uploads.get(instance.instance_id)
        if upload is None:
            raise CipError(GeneralStatus.OBJECT_STATE_CONFLICT, data=bytes((instance.values[1],)),
                           message="Upload_Transfer before Initiate_Upload")
        if len(request.data) != 1:
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA if not request.data else GeneralStatus.TOO_MUCH_DATA)
        number = request.data[0]
        if number == upload.next_packet & 0xFF:
            packet = upload.next_packet
        elif upload.last_sent >= 0 and number == upload.last_sent & 0xFF:
            packet = upload.last_sent  # a repeat: the same packet again
        else:
            raise CipError(GeneralStatus.INVALID_PARAMETER,
                           message=f"transfer number {number}, {upload.next_packet & 0xFF} expected")
        start = packet * upload.size
        chunk = upload.data[start:start + upload.size]
        last = start + upload.size >= len(upload.data)
        kind = (FIRST_AND_LAST if packet == 0 else LAST) if last else (FIRST if packet == 0 else MIDDLE)
        upload.last_sent, upload.next_packet = packet, packet + 1
        reply = bytes((number, kind)) + chunk
        if last:
            reply += struct.pack("<H", checksum(upload.data))
            instance.values[1] = FILE_LOADED
        else:
            instance.values[1] = UPLOAD_IN_PROGRESS
        return reply


# -- reading a file from a device ------------------------------------------------------------------------
#: The largest file ``read_file`` takes: an EDS file is well below (the ACG's is under 200 KB).
MAX_FILE_SIZE = 4 * 1024 * 1024


class FileTransferError(ProtocolError):
    """A device's File object did not give its file: a refused service or a malformed transfer."""


#: Sends one request to the File object instance: (service, data) -> (general status, reply data).
FileRequest = Callable[[int, bytes], tuple[int, bytes]]


def read_file(request: FileRequest, max_transfer: int = MAX_TRANSFER) -> bytes:
    """The file a File object instance holds, read with Initiate_Upload and Upload_Transfer through
    ``request`` (the same loop for any client: the scanner's, the conformance battery's). The size and
    the checksum are checked; a gzip or zlib file (encoding 1) is returned uncompressed."""
    status, data = request(INITIATE_UPLOAD, bytes((max_transfer,)))
    if status != 0:
        raise FileTransferError(f"Initiate_Upload answered general status 0x{status:02X}")
    if len(data) < 5:
        raise FileTransferError(f"Initiate_Upload reply of {len(data)} bytes, 5 expected")
    size, transfer = struct.unpack_from("<IB", data)
    if size > MAX_FILE_SIZE or transfer == 0:
        raise FileTransferError(f"file of {size} bytes in transfers of {transfer}: not read")
    content = bytearray()
    for packet in range(size // transfer + 2):  # one more for a Last packet with no data
        status, data = request(UPLOAD_TRANSFER, bytes((packet & 0xFF,)))
        if status != 0:
            raise FileTransferError(f"Upload_Transfer {packet} answered general status 0x{status:02X}")
        if len(data) < 2 or data[0] != packet & 0xFF:
            raise FileTransferError(f"Upload_Transfer {packet}: reply {data[:2].hex()} does not echo the number")
        kind, chunk = data[1], data[2:]
        if kind == ABORT:
            raise FileTransferError(f"the device aborted the upload at packet {packet}")
        if kind in (LAST, FIRST_AND_LAST):
            if len(chunk) < 2:
                raise FileTransferError("the last packet has no checksum")
            content += chunk[:-2]
            (sent,) = struct.unpack_from("<H", chunk, len(chunk) - 2)
            break
        content += chunk
    else:
        raise FileTransferError(f"no last packet after {size} bytes")
    if len(content) != size:
        raise FileTransferError(f"{len(content)} bytes received, the device announced {size}")
    if sent != checksum(bytes(content)):
        raise FileTransferError(f"checksum 0x{sent:04X}, the bytes make 0x{checksum(bytes(content)):04X}")
    return _uncompressed(bytes(content))


def write_file(request: FileRequest, data: bytes, name: str = "file", revision: tuple[int, int] = (1, 0)) -> None:
    """Download ``data`` into a File object instance with Initiate_Download and Download_Transfer
    through ``request``, in the transfer size the device chose; ``FileTransferError`` on a refusal."""
    initiate = struct.pack("<IHBB", len(data), 1, *revision) + stringi(name)
    status, reply = request(INITIATE_DOWNLOAD, initiate)
    if status != 0:
        raise FileTransferError(f"Initiate_Download answered general status 0x{status:02X}")
    if len(reply) < 7 or reply[6] == 0:
        raise FileTransferError(f"Initiate_Download reply {reply.hex()} gives no transfer size")
    size = reply[6]
    chunks = [data[i:i + size] for i in range(0, len(data), size)] or [b""]
    for number, chunk in enumerate(chunks):
        last = number == len(chunks) - 1
        kind = (FIRST_AND_LAST if number == 0 else LAST) if last else (FIRST if number == 0 else MIDDLE)
        body = bytes((number & 0xFF, kind)) + chunk + (struct.pack("<H", checksum(data)) if last else b"")
        status, reply = request(DOWNLOAD_TRANSFER, body)
        if status != 0:
            raise FileTransferError(f"Download_Transfer {number} answered general status 0x{status:02X}")


def _uncompressed(data: bytes) -> bytes:
    """Encoding 1 is "compressed": gzip (1F 8B) on some devices, zlib (78 xx) on others."""
    import gzip
    import zlib

    try:
        if data[:2] == b"\x1f\x8b":
            return gzip.decompress(data)
        if data[:1] == b"\x78" and int.from_bytes(data[:2], "big") % 31 == 0:
            return zlib.decompress(data)
    except (OSError, zlib.error, EOFError) as exc:
        raise FileTransferError(f"compressed file that does not decompress: {exc}") from None
    return data
