"""Read a BLF file that may be damaged: container by container, resynchronising after
corrupt bytes on the next intact container.

A BLF file is a file header followed by objects, each starting with a base header
(signature ``LOBJ``, header size, header version, object size, object type); at the
top level these are LOG_CONTAINER objects, zlib-compressed (or stored) runs of the CAN
objects, which may straddle two containers. python-can's `can.BLFReader` stops at the
first damaged object. Here the top level is walked with the documented layout
(python-can's public struct definitions) and every container is checked (a compressed
one must inflate completely, zlib's Adler-32 included, to its declared size); a damaged
object is skipped by scanning forward for the next ``LOBJ`` that is an intact container.
The CAN objects themselves are parsed by python-can: each run of intact containers is
handed to one `can.BLFReader` as a file of the original header and those containers
(stored uncompressed), the first container after a resync starting at its first whole
object. What a resync loses: the objects of the damaged container(s) and the object
straddling into the first intact one, nothing else.
"""

from __future__ import annotations

import mmap
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import BinaryIO

import can
from can.io.blf import (
    LOG_CONTAINER,
    LOG_CONTAINER_STRUCT,
    NO_COMPRESSION,
    OBJ_HEADER_BASE_STRUCT,
    ZLIB_DEFLATE,
)

_HEADER = OBJ_HEADER_BASE_STRUCT  # signature, header size, header version, size, type
_CONTAINER = LOG_CONTAINER_STRUCT  # compression method, uncompressed size
_SIGNATURE = b"LOBJ"
#: largest object (and inflated container) taken as plausible; loggers write ~128 KiB
MAX_OBJECT_BYTES = 16 * 1024 * 1024


class BlfDamage(Exception):
    """The object at a byte offset is not an intact BLF object (the reason says why)."""


@dataclass(frozen=True)
class Resync:
    """A damaged stretch: where it began, why, and where reading resumed (None: never)."""

    offset: int
    reason: str
    resumed_at: int | None

    @property
    def skipped(self) -> int:
        """Bytes skipped (to the resume point; 0 when reading did not resume)."""
        return 0 if self.resumed_at is None else self.resumed_at - self.offset


def _plausible_header(buf: bytes | mmap.mmap, pos: int, end: int) -> tuple[int, int] | None:
    """(object size, object type) of a plausible object header at ``pos``, else None."""
    if end - pos < _HEADER.size:
        return None
    signature, header_size, version, size, obj_type = _HEADER.unpack_from(buf, pos)
    if signature != _SIGNATURE or header_size not in (16, 32) or version not in (1, 2):
        return None
    if not _HEADER.size <= size <= MAX_OBJECT_BYTES:
        return None
    return size, obj_type


def _padding(size: int) -> int:
    """Bytes after an object of ``size`` before the next one (python-can's writer's rule)."""
    return size % 4


def first_object(data: bytes) -> int | None:
    """Offset of the first whole object in inflated container data: a plausible header
    whose successor (when it lies inside ``data``) is one too; None if there is none."""
    pos = data.find(_SIGNATURE)
    while pos >= 0:
        head = _plausible_header(data, pos, len(data))
        if head is not None:
            nxt = pos + head[0]
            if nxt >= len(data) or data.find(_SIGNATURE, nxt, nxt + 8) >= 0:
                return pos
        pos = data.find(_SIGNATURE, pos + 1)
    return None


def _stored_container(data: bytes) -> bytes:
    """``data`` as one uncompressed LOG_CONTAINER object (with python-can's padding)."""
    size = _HEADER.size + _CONTAINER.size + len(data)
    head = _HEADER.pack(_SIGNATURE, _HEADER.size, 1, size, LOG_CONTAINER)
    return head + _CONTAINER.pack(NO_COMPRESSION, len(data)) + data + bytes(_padding(size))


@dataclass(frozen=True)
class _Container:
    """An intact container: its offset in the file, its inflated data, and whether
    damage was skipped right before it."""

    offset: int
    data: bytes
    after_damage: bool


@dataclass
class _RunState:
    """Where a run of containers is: the container being read, the one that ended it."""

    current: int = 0
    next: _Container | None = None


class _Feed:
    """A read-only file for python-can: the original file header, then containers
    pulled one at a time from ``chunks``; b"" when they run out."""

    def __init__(self, header: bytes, chunks: Iterator[bytes]) -> None:
        self._buf = bytearray(header)
        self._chunks = chunks
        self.closed = False

    def read(self, n: int = -1) -> bytes:
        while n < 0 or len(self._buf) < n:
            chunk = next(self._chunks, None)
            if chunk is None:
                break
            self._buf += chunk
        if n < 0:
            n = len(self._buf)
        out = bytes(self._buf[:n])
        del self._buf[:n]
        return out

    def close(self) -> None:
        self.closed = True


class BlfScanner:
    """The frames of a BLF file, resynchronising after damage (module docstring).

    ``on_resync`` is called for each damaged stretch as it is found; ``resyncs`` lists
    them. A container cut by the end of the file gives the frames that inflate; the
    caller compares the file's size with its header to report the truncation.
    """

    def __init__(
        self, file: BinaryIO, header_size: int, on_resync: Callable[[Resync], None]
    ) -> None:
        self._file = file
        self._header_size = header_size
        self._on_resync = on_resync
        self.resyncs: list[Resync] = []

    def __iter__(self) -> Iterator[can.Message]:
        self._file.seek(0)
        header = self._file.read(self._header_size)
        size = self._file.seek(0, 2)
        if size <= self._header_size:
            return
        with mmap.mmap(self._file.fileno(), 0, access=mmap.ACCESS_READ) as buf:
            items = self._containers(buf, size)
            state = _RunState()
            item = next(items, None)
            while item is not None:
                state.next = None
                reader = can.BLFReader(_Feed(header, self._run(item, items, state)))  # type: ignore[arg-type]  # read() is all it uses
                try:
                    yield from reader
                except Exception as exc:  # python-can found a damaged object in the data
                    item = state.next if state.next is not None else next(items, None)
                    resume = None if item is None else item.offset
                    self._resync(state.current, f"bad CAN object ({exc!r})", resume)
                    continue
                item = state.next if state.next is not None else next(items, None)

    def _run(
        self, first: _Container, items: Iterator[_Container], state: _RunState
    ) -> Iterator[bytes]:
        """Stored containers for one python-can reader: ``first`` from its first whole
        object, then the intact ones that follow it without damage in between."""
        start = first_object(first.data)
        while start is None:  # no whole object in it: the next one starts the run
            nxt = next(items, None)
            if nxt is None:
                return
            first, start = nxt, first_object(nxt.data)
        state.current = first.offset
        yield _stored_container(first.data[start:])
        for item in items:
            if item.after_damage:
                state.next = item
                return
            state.current = item.offset
            yield _stored_container(item.data)

    def _resync(self, offset: int, reason: str, resumed_at: int | None) -> None:
        event = Resync(offset, reason, resumed_at)
        self.resyncs.append(event)
        self._on_resync(event)

    def _containers(self, buf: mmap.mmap, end: int) -> Iterator[_Container]:
        """Each intact container, resynchronising after damage."""
        pos = self._header_size
        damaged = False
        while pos < end:
            if end - pos < _HEADER.size:
                return  # a cut header: the truncation check reports it
            try:
                size, obj_type, data = self._object_at(buf, pos, end)
            except BlfDamage as exc:
                resume = self._scan(buf, pos + 1, end)
                self._resync(pos, str(exc), resume)
                if resume is None:
                    return
                pos, damaged = resume, True
                continue
            if data is not None:
                yield _Container(pos, data, damaged)
                damaged = False
            elif obj_type == LOG_CONTAINER:
                return  # a container cut by the end of the file, nothing inflatable
            pos = self._next(buf, pos + size, end)

    @staticmethod
    def _next(buf: mmap.mmap, pos: int, end: int) -> int:
        """The next object after one ending at ``pos``: after python-can's padding, or
        wherever ``LOBJ`` starts in the next 4 bytes (other writers pad differently)."""
        for cand in (pos + _padding(pos), pos, pos + 1, pos + 2, pos + 3):
            if cand + 4 <= end and buf[cand : cand + 4] == _SIGNATURE:
                return cand
        return pos + _padding(pos) if pos < end else end

    @staticmethod
    def _object_at(buf: mmap.mmap, pos: int, end: int) -> tuple[int, int, bytes | None]:
        """(size, type, inflated data for a container else None) of the object at
        ``pos``; a container cut by the end of the file gives the data that inflates.
        Raises `BlfDamage`."""
        head = _plausible_header(buf, pos, end)
        if head is None:
            raise BlfDamage("no valid object header")
        size, obj_type = head
        if obj_type != LOG_CONTAINER:
            if pos + size > end:
                raise BlfDamage(f"object of {size} bytes runs past the end of the file")
            return size, obj_type, None  # not CAN data at this level: skipped, as python-can
        if size < _HEADER.size + _CONTAINER.size:
            raise BlfDamage(f"container of {size} bytes is smaller than its header")
        method, declared = _CONTAINER.unpack_from(buf, pos + _HEADER.size)
        stop = pos + size
        cut = stop > end
        payload = buf[pos + _HEADER.size + _CONTAINER.size : min(stop, end)]
        if declared > MAX_OBJECT_BYTES:
            raise BlfDamage(f"container declares {declared} bytes")
        if method == NO_COMPRESSION:
            data = bytes(payload)
        elif method == ZLIB_DEFLATE:
            inflater = zlib.decompressobj()
            try:
                data = inflater.decompress(payload, declared + 1)
            except zlib.error as exc:
                raise BlfDamage(f"container does not inflate ({exc})") from None
            if not cut and not inflater.eof:
                raise BlfDamage("container's zlib stream is incomplete")
        else:
            raise BlfDamage(f"unknown compression method {method}")
        if cut:
            return size, obj_type, data  # a truncated file: what inflates is genuine
        if len(data) != declared:
            raise BlfDamage(f"container holds {len(data)} bytes, declares {declared}")
        return size, obj_type, data

    def _scan(self, buf: mmap.mmap, pos: int, end: int) -> int | None:
        """The next intact, complete container from ``pos``, or None."""
        cand = buf.find(_SIGNATURE, pos)
        while cand >= 0:
            try:
                size, obj_type, _ = self._object_at(buf, cand, end)
            except BlfDamage:
                pass
            else:
                if obj_type == LOG_CONTAINER and cand + size <= end:
                    return cand
            cand = buf.find(_SIGNATURE, cand + 1)
        return None
