"""Read and write ASCII MPEG-4 FAP files (``.fap``): the takes the rig records and plays back.

A ``.fap`` file is an optional header line ``<version> <name> <fps> <nframes>`` followed, per
frame, by a mask line of 68 flags (FAPs 1..68) and a value line ``<frame#> <values of the masked
FAPs>``. The reader accepts every variant described in ``shared/reference/FAP-FORMAT.md`` and seen
in ``shared/fap-corpus/``; the writer emits only the portable form that every reader accepts.
Values are read with their standard meaning (FAPU units, angles in 1e-5 rad): the scalings other
players apply (Xface, C++ Greta, VREng's version-2.0 division by 20) are not copied.

Decisions
---------
* **Stream layout.** ``values`` is (frames, 68) float, column 0 = FAP 1. Columns 0 and 1 hold
  ``viseme_select1`` and ``expression_select1``; the full FAP 1 / FAP 2 fields are in ``viseme``
  (frames, 4: select1, select2, blend, def) and ``expression`` (frames, 6: select1, intensity1,
  select2, intensity2, init_face, def). Where a FAP is not masked its value (and fields) are 0:
  holding the previous value is the player's business, the stream keeps what the file says.
* **FAP 1 / FAP 2 with one token** (Java Greta and the C++ Greta writer): per value line,
  ``extra = tokens - 1 - (masked FAPs 3..68)``; 1 or 2 means one token each, 4, 6 or 10 the full
  fields. The single token is the select: FAP 1 reads as ``(token, 0, 63, 0)`` -- blend 63 means
  wholly select1 by the rule ``v1*blend/63 + v2*(1-blend/63)``; FAP 2 reads as
  ``(token, 63, 0, 0, 0, 0)`` -- expression select1 at full intensity. (The corpus has one such
  file, ``greta_1-Welcome_1.fap``: FAP 1 = 0, no viseme; no public file masks FAP 2.)
* **69-flag masks.** Java Greta sizes its FAP frame as ``FAPType.NUMFAPS = 70`` (counting
  ``null_fap``) and writes slots 1..69: FAPs 1..68 and then an unused 69th slot. The corpus
  confirms it: ``greta_AU_Interpolation_1131.fap`` flags eyelid pairs 19-22 (626, 626, 133, 133)
  only when the *last* flag is dropped, and ``greta_1-Welcome_1.fap`` then masks FAP 1 with its one
  token. So the last flag is dropped, unless only the last flag is set and the first is not -- that
  can only be a writer that put an unused slot 0 first. Both ends set is an error.
* **Value line with only the frame number** (``greta_cpp_empty.fap``): it transmits no FAP. With an
  empty mask this is simply consistent; where its mask line set FAPs the frame is read with an
  empty mask and the reader warns once per file. Any other count mismatch is an error.
* **No header**: fps defaults to ``DEFAULT_FPS`` = 25 (the rate of every headed corpus file from a
  live system) with a warning; ``name`` and ``version`` are ``""``, ``declared_frames`` None.
* **Declared vs present frames**: fewer present (how a crashed take looks) or more present both
  warn and keep every frame there is. A last frame cut off mid-line (the file ends without its
  newline, or a mask line without its value line) that the header's count leaves out is what a
  killed ``FapWriter`` leaves: it is dropped with a warning. Anywhere else it is an error.
* **No clamping**: every value is returned exactly as the file writes it, however far beyond the
  Greta editor's slider ranges of ``fap_coding_params.csv`` (those are an editor's convention, not
  the standard's limits: real files turn the head 30 degrees). What a face cannot follow is
  limited when it is posed (``puppet.runtime.fapengine``), never in the stream. FAP 1/2 fields are whole
  numbers (selects beyond 0-14 / 0-6 are kept as written too).
* **Numbers** are ASCII decimals (``-12``, ``3.5``, ``1e3``); Python's extras (``1_000``,
  ``inf``, ``nan``, non-ASCII digits) are errors, and so is anything a sane file never holds:
  a frame number or FAP 1/2 field of more than ``MAX_DIGITS`` digits, an fps outside
  ``MIN_FPS``-``MAX_FPS``, a declared count of more than ``COUNT_WIDTH`` digits.
* **Bounded work**: lines are read in pieces of ``CHUNK`` characters; a line of more than
  ``MAX_FIELDS`` fields or a field of more than ``MAX_FIELD_CHARS`` characters is an error as soon
  as it is seen, and a comment line of any length is skipped piece by piece, so no input makes the
  reader hold more than a few pieces at once. Streaming readers emit the warnings that summarise a
  file when they reach its end.
* **API**: ``read_fap`` (whole file, ``FapStream``) is built on ``iter_fap`` (a ``FapReader``:
  ``.header`` as soon as it is opened, then ``FapFrame``s one line pair at a time);
  ``write_fap`` (a whole take) is built on ``FapWriter`` (frame by frame, live).
* **Errors**: every problem is a ``FapError`` ``"{file}:{line}: expected ..., found ..."``.
* **Writing** (``write_fap``, ``FapWriter``): ``2.1 <name, whitespace -> _> <integer fps> <n>``,
  68 flags, frames numbered from 0, values rounded to integers (written out in full, so any
  finite value reads back as written), LF. FAP 1/2 are masked only in
  frames that use them and then carry their full 4/6 fields. A non-integer fps is rounded, with a
  warning, because the portable header carries an integer.
* **Header count while recording**: ``FapWriter`` reserves the count as a fixed-width field
  ``COUNT_WIDTH`` wide, left-aligned and padded with trailing spaces (``"2.1 take 25 42        "``)
  and rewrites it in place after every frame, flushed. Trailing spaces are whitespace to every
  tokenising reader (corpus lines end in spaces too), unlike zero padding, which a C ``%i`` reads
  as octal. A killed process therefore leaves a file whose count matches its complete frames,
  except in the instant between a frame's flush and its count update (then the count is one short,
  which the reader accepts with a warning). ``fsync=True`` also syncs to disk after every frame.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import IO

import numpy as np

from puppet.errors import PuppetError
from puppet.fap.frame import FapFrame
from puppet.fap.table import N_FAPS

DEFAULT_FPS = 25.0
VERSION = "2.1"
COUNT_WIDTH = 10
VISEME_FIELDS = ("select1", "select2", "blend", "def")
EXPRESSION_FIELDS = ("select1", "intensity1", "select2", "intensity2", "init_face", "def")
MIN_FPS, MAX_FPS = 0.1, 10_000.0
MAX_DIGITS = 15                 # frame numbers and FAP 1/2 fields
MAX_FIELDS = 256                # a valid line has at most 78 (a header's name can add a few)
MAX_FIELD_CHARS = 400           # the largest double written out in full has 309 digits
CHUNK = 1 << 16                 # characters read at once from a line
_FLAGS = frozenset(("0", "1"))
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_INTEGER = re.compile(r"[+-]?[0-9]+")


class FapError(PuppetError, ValueError):
    """A problem in a .fap file: ``"{file}:{line}: expected ..., found ..."``."""


class FapWarning(UserWarning):
    """Something in a .fap file was read leniently (missing header, count mismatch...)."""


@dataclass(frozen=True)
class FapHeader:
    """The header line; ``version``/``name`` are "" and ``declared_frames`` None without one."""

    version: str
    name: str
    fps: float
    declared_frames: int | None


@dataclass
class FapStream:
    """A whole FAP stream; see the module docstring for the meaning of each array."""

    fps: float
    values: np.ndarray          # (frames, 68) float, FAPU; columns 0/1: select1 of FAP 1/2
    mask: np.ndarray            # (frames, 68) bool
    viseme: np.ndarray          # (frames, 4) int: VISEME_FIELDS
    expression: np.ndarray      # (frames, 6) int: EXPRESSION_FIELDS
    frame_numbers: np.ndarray   # (frames,) int, as written in the file
    name: str = ""
    version: str = VERSION
    declared_frames: int | None = None

    def __len__(self) -> int:
        return len(self.values)


def _fail(label: str, line: int, expected: str, found: str) -> FapError:
    return FapError(f"{label}:{line}: {expected}, found {found}")


def _show(tokens: Sequence[str], limit: int = 40) -> str:
    text = " ".join(tokens)
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _is_mask(tokens: Sequence[str]) -> bool:
    return len(tokens) in (N_FAPS, N_FAPS + 1) and _FLAGS.issuperset(tokens)


class FapReader:
    """Streaming reader: ``.header`` is parsed on opening; iterating yields ``FapFrame``s.

    Reads line by line, so a file of any length streams in constant memory. Use it as a context
    manager (or exhaust it) to close the file.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.label = str(path)
        self._file: IO[str] = open(path, encoding="utf-8", errors="replace")
        self._last_line = 0
        self._line_ended = True
        self._lines = self._content_lines()
        try:
            self.header, self._pending = self._read_header()
        except BaseException:
            self.close()
            raise
        self._frames = self._read_frames()

    def __iter__(self) -> FapReader:
        return self

    def __next__(self) -> FapFrame:
        return next(self._frames)

    def __enter__(self) -> FapReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._file.close()

    def _content_lines(self) -> Iterator[tuple[int, list[str]]]:
        """(line number, tokens) of every line that is neither blank nor a # comment."""
        number = 0
        while text := self._file.readline(CHUNK):
            number = self._last_line = number + 1
            self._line_ended = text.endswith("\n")
            if text.endswith("\n") or len(text) < CHUNK:
                tokens = self._checked(number, text.split(), "")
            else:
                tokens = self._long_line(number, text)
            if tokens and not tokens[0].startswith("#"):
                yield number, tokens

    def _long_line(self, number: int, text: str) -> list[str]:
        """The tokens of a line longer than ``CHUNK``, read piece by piece (a comment: skipped)."""
        tokens: list[str] = []
        carry = ""
        while True:
            done = text.endswith("\n") or len(text) < CHUNK
            text = carry + text
            parts = text.split()
            carry = "" if done or not parts or text[-1].isspace() else parts.pop()
            first = (tokens or parts or [carry])[0]
            if first.startswith("#"):
                while not done:
                    text = self._file.readline(CHUNK)
                    done = text.endswith("\n") or len(text) < CHUNK
                return []
            tokens = self._checked(number, tokens + parts, carry)
            if done:
                self._line_ended = text.endswith("\n")
                return tokens
            text = self._file.readline(CHUNK)

    def _checked(self, number: int, tokens: list[str], carry: str) -> list[str]:
        """``tokens``, if neither they nor the field still being read exceed the bounds."""
        if tokens and tokens[0].startswith("#"):
            return tokens
        if len(tokens) > MAX_FIELDS:
            raise _fail(self.label, number, f"expected a line of at most {MAX_FIELDS} fields",
                        f"{len(tokens)} or more")
        longest = max([carry, *tokens], key=len)
        if len(longest) > MAX_FIELD_CHARS:
            raise _fail(self.label, number, f"expected fields of at most {MAX_FIELD_CHARS}"
                        " characters", f"one of {len(longest)} or more starting {longest[:20]!r}")
        return tokens

    def _eof(self) -> int:
        return self._last_line + 1

    def _read_header(self) -> tuple[FapHeader, tuple[int, list[str]] | None]:
        first = next(self._lines, None)
        if first is None:
            raise _fail(self.label, self._eof(), "expected a header or a mask line", "end of file")
        number, tokens = first
        if _is_mask(tokens):
            warnings.warn(f"{self.label}: no header line; assuming {DEFAULT_FPS:g} fps", FapWarning,
                          stacklevel=3)
            return FapHeader("", "", DEFAULT_FPS, None), first
        return self._parse_header(number, tokens), None

    def _parse_header(self, number: int, tokens: list[str]) -> FapHeader:
        if len(tokens) < 3 or not _is_number(tokens[0]):
            raise _fail(self.label, number, "expected a header '<version> <name> <fps> <nframes>'"
                        " or a mask line of 68 flags", _show(tokens))
        fps = float(tokens[-2]) if _is_number(tokens[-2]) else 0.0
        if not MIN_FPS <= fps <= MAX_FPS:
            raise _fail(self.label, number, f"expected the fps (a number from {MIN_FPS:g} to"
                        f" {MAX_FPS:g}) as the second-last header field", repr(tokens[-2]))
        if not (_is_int(tokens[-1], COUNT_WIDTH) and int(tokens[-1]) >= 0):
            raise _fail(self.label, number, f"expected the frame count (an integer >= 0 of at most"
                        f" {COUNT_WIDTH} digits) as the last header field", repr(tokens[-1]))
        return FapHeader(tokens[0], " ".join(tokens[1:-2]), fps, int(tokens[-1]))

    def _read_frames(self) -> Iterator[FapFrame]:
        tally = _Tally()
        parsed_mask: tuple[list[str], _Mask] | None = None
        with self._file:
            lines = self._lines
            if self._pending is not None:
                lines = _chain(self._pending, lines)
            for mask_line, tokens in lines:
                value_line = None
                try:
                    if parsed_mask is None or tokens != parsed_mask[0]:
                        parsed_mask = (tokens, self._parse_mask(mask_line, tokens))
                    value_line = next(lines, None)
                    if value_line is None:
                        raise _fail(self.label, self._eof(), f"expected the value line of the mask"
                                    f" line {mask_line}", "end of file")
                    frame = self._parse_values(*value_line, parsed_mask[1], tally)
                    if self._cut_short(tally, False):
                        raise _fail(self.label, value_line[0], "expected a value line ending in a"
                                    " newline", "end of file")
                except FapError as error:
                    if not self._cut_short(tally, value_line is None):
                        raise
                    tally.cut = str(error)
                    break
                yield frame
                tally.frames += 1
        self._summarise(tally)

    def _cut_short(self, tally: _Tally, no_values: bool) -> bool:
        """Whether this frame is a recorder's last, cut off by a kill: it ends the file without
        its newline (only the file's last line can) or lacks its value line, and the header's
        count leaves it out."""
        declared = self.header.declared_frames
        if declared is None or declared > tally.frames:
            return False
        return no_values or not self._line_ended

    def _parse_mask(self, number: int, tokens: list[str]) -> _Mask:
        if not _is_mask(tokens):
            bad = next((t for t in tokens if t not in _FLAGS), None)
            found = f"{len(tokens)} flags" if bad is None else f"{bad!r} among {len(tokens)} tokens"
            raise _fail(self.label, number, "expected a mask line of 68 flags (0 or 1)", found)
        if len(tokens) > N_FAPS:
            tokens = self._drop_extra_slot(number, tokens)
        return _Mask(np.array([t == "1" for t in tokens]))

    def _drop_extra_slot(self, number: int, tokens: list[str]) -> list[str]:
        first, last = tokens[0] == "1", tokens[-1] == "1"
        if first and last:
            raise _fail(self.label, number, "expected a 69-flag mask with its extra slot (the first"
                        " or the last flag) unset", "both set")
        return tokens[1:] if last else tokens[:N_FAPS]

    def _parse_values(self, number: int, tokens: list[str], mask: _Mask, tally: _Tally) -> FapFrame:
        if not _is_int(tokens[0], MAX_DIGITS):
            raise _fail(self.label, number, f"expected a frame number (an integer of at most"
                        f" {MAX_DIGITS} digits) starting the value line", repr(tokens[0]))
        numbers = self._numbers(number, tokens[1:], mask)
        if not len(numbers) and mask.count:
            tally.note_empty(number)
            mask = _EMPTY_MASK
        full = len(numbers) - mask.n_low > mask.n_single
        values = np.zeros(N_FAPS)
        values[mask.low] = numbers[len(numbers) - mask.n_low:]
        viseme, expression, rest = np.zeros(4, int), np.zeros(6, int), numbers
        for column, fields, defaults in ((0, viseme, (0, 63, 0)), (1, expression, (63, 0, 0, 0, 0))):
            if mask.mask[column]:
                taken = _fields(rest, full, defaults)
                self._check_fields(number, column, taken)
                fields[:], rest = taken, rest[len(taken) if full else 1:]
        values[0], values[1] = viseme[0], expression[0]
        return FapFrame(int(tokens[0]), values, mask.mask.copy(), viseme, expression)

    def _check_fields(self, number: int, column: int, fields: np.ndarray) -> None:
        whole = (fields == np.round(fields)) & (np.abs(fields) < 10.0 ** MAX_DIGITS)
        if not whole.all():
            names = VISEME_FIELDS if column == 0 else EXPRESSION_FIELDS
            bad = int(np.argmin(whole))
            raise _fail(self.label, number, f"expected FAP {column + 1}'s {names[bad]} as a whole"
                        f" number of at most {MAX_DIGITS} digits", f"{fields[bad]:g}")

    def _numbers(self, number: int, tokens: list[str], mask: _Mask) -> np.ndarray:
        if tokens and len(tokens) - mask.n_low not in mask.extras:
            raise _fail(self.label, number, f"expected {mask.describe()}", f"{len(tokens)} values")
        text = "".join(tokens)
        try:
            numbers = np.array(list(map(float, tokens)))
        except ValueError:
            numbers = np.array([math.nan])
        if "_" in text or not text.isascii() or not np.isfinite(numbers).all():
            position, token = next((i, t) for i, t in enumerate(tokens, 1) if not _is_number(t))
            raise _fail(self.label, number, f"expected a number as value {position} of the"
                        " value line", repr(token))
        return numbers

    def _summarise(self, tally: _Tally) -> None:
        declared = self.header.declared_frames
        if declared is not None and declared != tally.frames:
            why = " (a take cut short?)" if declared > tally.frames else ""
            warnings.warn(f"{self.label}: the header declares {declared} frames, the file holds"
                          f" {tally.frames}{why}; keeping {tally.frames}", FapWarning, stacklevel=3)
        for message in tally.messages(self.label):
            warnings.warn(message, FapWarning, stacklevel=3)


class _Mask:
    """A parsed mask line and what it implies for its value lines."""

    def __init__(self, mask: np.ndarray) -> None:
        self.mask = mask
        self.low = np.flatnonzero(mask[2:]) + 2
        self.n_low = len(self.low)
        self.count = int(mask.sum())
        ones = {(False, False): 0, (True, False): 1, (False, True): 1, (True, True): 2}
        full = {(False, False): 0, (True, False): 4, (False, True): 6, (True, True): 10}
        key = (bool(mask[0]), bool(mask[1]))
        self.n_single = ones[key]
        self.extras = {ones[key], full[key]}

    def describe(self) -> str:
        counts = sorted({self.n_low + e for e in self.extras})
        what = " or ".join(str(c) for c in counts)
        return f"{what} values after the frame number (its mask line sets {self.count} FAPs)"


_EMPTY_MASK = _Mask(np.zeros(N_FAPS, bool))


class _Tally:
    """What a file's reading accumulates for its end-of-file warnings."""

    def __init__(self) -> None:
        self.frames = 0
        self.empty_lines = 0
        self.first_empty = 0
        self.cut = ""

    def note_empty(self, line: int) -> None:
        self.first_empty = self.first_empty or line
        self.empty_lines += 1

    def messages(self, label: str) -> list[str]:
        out = []
        if self.empty_lines:
            out.append(f"{label}: {self.empty_lines} value line(s) hold only the frame number although"
                       f" their mask line sets FAPs (first at line {self.first_empty}); read as"
                       " frames that transmit no FAP")
        if self.cut:
            out.append(f"{self.cut}: the last frame was cut off (a recorder killed mid-write);"
                       f" keeping the {self.frames} complete frames before it")
        return out


def _chain(first: tuple[int, list[str]],
           rest: Iterator[tuple[int, list[str]]]) -> Iterator[tuple[int, list[str]]]:
    yield first
    yield from rest


def _fields(numbers: np.ndarray, full: bool, defaults: tuple[int, ...]) -> np.ndarray:
    """One FAP 1/2 from the front of ``numbers``: all its fields, or a select + defaults."""
    if full:
        return numbers[:len(defaults) + 1]
    return np.array([numbers[0], *defaults], dtype=float)


def _is_number(token: str) -> bool:
    return bool(_NUMBER.fullmatch(token)) and math.isfinite(float(token))


def _is_int(token: str, digits: int = MAX_DIGITS) -> bool:
    return bool(_INTEGER.fullmatch(token)) and len(token.lstrip("+-")) <= digits


def iter_fap(path: str | os.PathLike[str]) -> FapReader:
    """Stream a .fap file: the result has ``.header`` now and yields ``FapFrame``s lazily."""
    return FapReader(path)


def read_fap(path: str | os.PathLike[str]) -> FapStream:
    """Read a whole .fap file into a ``FapStream`` (built on ``iter_fap``)."""
    with iter_fap(path) as reader:
        frames = list(reader)
        header = reader.header
    if frames:
        stack = {k: np.stack([getattr(f, k) for f in frames])
                 for k in ("values", "mask", "viseme", "expression")}
    else:
        stack = {"values": np.zeros((0, N_FAPS)), "mask": np.zeros((0, N_FAPS), bool),
                 "viseme": np.zeros((0, 4), int), "expression": np.zeros((0, 6), int)}
    return FapStream(fps=header.fps, frame_numbers=np.array([f.number for f in frames], int),
                     name=header.name, version=header.version,
                     declared_frames=header.declared_frames, **stack)


class FapWriter:
    """Write a take frame by frame; the file is a valid .fap after every ``write_frame``.

    ``flush=True`` (the default) flushes each frame and rewrites the header's fixed-width frame
    count in place, so a killed process leaves every completed frame readable with an exact
    count; ``fsync=True`` also syncs to disk. ``flush=False`` writes the count on ``close`` only.
    """

    def __init__(self, path: str | os.PathLike[str], fps: float = DEFAULT_FPS, name: str = "take",
                 *, flush: bool = True, fsync: bool = False) -> None:
        head = f"{VERSION} {_portable_name(name)} {_portable_fps(fps)} ".encode()
        self.frames_written = 0
        self._count_at = len(head)
        self._flush, self._fsync = flush, fsync
        self._file = open(path, "wb")
        self._file.write(head + self._count_field() + b"\n")
        self._sync()

    def __enter__(self) -> FapWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def write_frame(self, values: Sequence[float] | np.ndarray,
                    mask: Sequence[bool] | np.ndarray | None = None,
                    viseme: Sequence[float] | np.ndarray | None = None,
                    expression: Sequence[float] | np.ndarray | None = None) -> None:
        """Append one frame.

        ``values`` (68,) in FAPU units. ``mask`` None = FAPs 3..68, plus FAP 1 / FAP 2 when
        ``viseme`` / ``expression`` is given; otherwise the mask decides for all 68 FAPs. A masked
        FAP 1/2 writes ``viseme`` (4) / ``expression`` (6), or, when those are None, the full
        fields of the select in ``values[0]`` / ``values[1]`` (as the reader reads one token).
        """
        if self._file.closed:
            raise ValueError("write_frame on a closed FapWriter")
        line = _format_frame(self.frames_written, values, mask, viseme, expression)
        self._file.write(line)
        self.frames_written += 1
        if self._flush:
            self._file.flush()
            self._write_count()

    def close(self) -> None:
        """Write the final frame count and close the file."""
        if self._file.closed:
            return
        self._write_count()
        self._file.close()

    def _count_field(self) -> bytes:
        text = str(self.frames_written)
        if len(text) > COUNT_WIDTH:
            raise ValueError(f"more than {COUNT_WIDTH} digits of frames")
        return text.ljust(COUNT_WIDTH).encode()

    def _write_count(self) -> None:
        self._file.seek(self._count_at)
        self._file.write(self._count_field())
        self._file.seek(0, os.SEEK_END)
        self._sync()

    def _sync(self) -> None:
        self._file.flush()
        if self._fsync:
            os.fsync(self._file.fileno())


def _portable_name(name: str) -> str:
    return "_".join(str(name).split()) or "take"


def _portable_fps(fps: float) -> int:
    fps = float(fps)
    if not 0.0 < fps < math.inf or round(fps) < 1:
        raise ValueError(f"fps must be a positive number (at least 0.5), got {fps}")
    if fps != round(fps):
        warnings.warn(f"fps {fps:g} written as {round(fps)}: the portable header carries an"
                      " integer fps", FapWarning, stacklevel=3)
    return round(fps)


def _format_frame(number: int, values: Sequence[float] | np.ndarray,
                  mask: Sequence[bool] | np.ndarray | None,
                  viseme: Sequence[float] | np.ndarray | None,
                  expression: Sequence[float] | np.ndarray | None) -> bytes:
    values = np.asarray(values, dtype=float)
    if values.shape != (N_FAPS,):
        raise ValueError(f"values must be {N_FAPS} numbers, got shape {values.shape}")
    if mask is None:
        flags = np.ones(N_FAPS, bool)
        flags[0], flags[1] = viseme is not None, expression is not None
    else:
        flags = np.asarray(mask, dtype=bool)
        if flags.shape != (N_FAPS,):
            raise ValueError(f"mask must be {N_FAPS} flags, got shape {flags.shape}")
    if not np.isfinite(values[2:][flags[2:]]).all():
        raise ValueError("masked values must be finite")
    tokens = [str(number)]
    if flags[0]:
        tokens += _field_tokens(viseme, values[0], 4, (0, 63, 0))
    if flags[1]:
        tokens += _field_tokens(expression, values[1], 6, (63, 0, 0, 0, 0))
    tokens += _whole(values[2:][flags[2:]])
    mask_line = " ".join(map(str, flags.view(np.uint8).tolist()))
    return f"{mask_line}\n{' '.join(tokens)}\n".encode()


def _field_tokens(fields: Sequence[float] | np.ndarray | None, select: float, size: int,
                  defaults: tuple[int, ...]) -> list[str]:
    if fields is None:
        fields = [select, *defaults]
    array = np.asarray(fields, dtype=float)
    if array.shape != (size,) or not (np.abs(array) < 10.0 ** MAX_DIGITS).all():
        raise ValueError(f"FAP 1 takes 4 fields and FAP 2 takes 6, each a whole number of at most"
                         f" {MAX_DIGITS} digits, got {array.tolist()}")
    return _whole(array)


def _whole(values: np.ndarray) -> list[str]:
    """Finite values rounded to integers and written out in full (no exponent, no -0)."""
    return [f"{v:.0f}" for v in (np.rint(values) + 0.0).tolist()]


def write_fap(path: str | os.PathLike[str],
              stream_or_arrays: FapStream | np.ndarray | tuple[np.ndarray, np.ndarray],
              fps: float | None = None, name: str | None = None) -> None:
    """Write a take in the portable form.

    ``stream_or_arrays``: a ``FapStream`` (its mask and FAP 1/2 fields; fps and name from it
    unless given), ``(values, mask)`` or ``values`` alone, (frames, 68). Without a mask, every
    frame masks the FAPs whose column is nonzero somewhere in the take (a column that is zero
    throughout reads back as zero anyway). From arrays, a masked FAP 1/2 is written as the full
    fields of the select in column 0/1. fps defaults to ``DEFAULT_FPS`` for arrays, name to "take".
    """
    viseme = expression = None
    if isinstance(stream_or_arrays, FapStream):
        stream = stream_or_arrays
        values, mask = stream.values, stream.mask
        viseme, expression = stream.viseme, stream.expression
        fps = stream.fps if fps is None else fps
        name = stream.name if name is None else name
    elif isinstance(stream_or_arrays, tuple):
        values, mask = (np.asarray(a) for a in stream_or_arrays)
    else:
        values = np.asarray(stream_or_arrays, dtype=float)
        mask = np.broadcast_to((values != 0).any(axis=0), values.shape)
    if values.ndim != 2 or values.shape[1] != N_FAPS or mask.shape != values.shape:
        raise ValueError(f"values and mask must be (frames, {N_FAPS}), got {values.shape}"
                         f" and {mask.shape}")
    with FapWriter(path, DEFAULT_FPS if fps is None else fps, name or "take", flush=False) as out:
        for i in range(len(values)):
            out.write_frame(values[i], mask[i],
                            None if viseme is None else viseme[i],
                            None if expression is None else expression[i])
