"""Read and write BVH motion files for any skeleton, with numpy only.

The reader accepts any hierarchy (several ROOTs, 0-channel dummy joints, any
non-repeating subset of the six channels in any order, End Sites with or
without OFFSET), any line ends and any wrapping of the motion values. Every
malformed input raises `BVHError` naming the file, the 1-based line and what
was expected. The hierarchy is parsed iteratively; the motion block is
converted in one vectorised call and only scanned line by line to locate an
error.
"""

from __future__ import annotations

import io
import os
import re
import stat
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from .atomic import write_chunks_atomic
from .errors import BVHError, SinMDMError

MAX_JOINTS = 10_000
MAX_DEPTH = 1_000  # nested blocks (joints and End Sites); real rigs stay under ~100
MAX_FILE_BYTES = 1 << 30
# Frames times joints bounds the memory of a clip's animation (about 100 bytes each as
# float64 matrices and translations): 20 M is an hour of a 90-joint rig at 60 fps.
MAX_JOINT_FRAMES = 20_000_000
MIN_FRAME_TIME, MAX_FRAME_TIME = 1e-4, 10.0  # seconds: 10,000 fps .. one frame per 10 s
FLOAT32_MAX = float(np.finfo(np.float32).max)

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_CANONICAL_CHANNEL = {name.lower(): name for name in CHANNEL_NAMES}
_KEYWORDS = {"HIERARCHY", "ROOT", "JOINT", "END", "OFFSET", "CHANNELS", "MOTION", "{", "}"}
_FRAMES_LINE = re.compile(r"frames\s*:?\s*(.*)", re.IGNORECASE)
_FRAME_TIME_LINE = re.compile(r"frame\s*time\s*:?\s*(.*)", re.IGNORECASE)
_INTEGER = re.compile(r"[+-]?\d+")


# --------------------------------------------------------------------------- data


@dataclass(frozen=True, eq=False)
class Skeleton:
    names: tuple[str, ...]
    parents: np.ndarray  # int64 (J,), -1 for a ROOT, parents[j] < j
    offsets: np.ndarray  # float64 (J, 3)
    channels: tuple[tuple[str, ...], ...]  # canonical names, file order
    end_sites: tuple[tuple[int, np.ndarray | None], ...] = ()

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        count = len(names)
        parents = _frozen_array(self.parents, np.int64)
        offsets = _frozen_array(self.offsets, np.float64)
        channels = tuple(tuple(_CANONICAL_CHANNEL.get(str(c).lower(), str(c)) for c in cs) for cs in self.channels)
        end_sites = tuple(
            (int(p), None if o is None else _frozen_array(o, np.float64)) for p, o in self.end_sites
        )
        if parents.shape != (count,) or offsets.shape != (count, 3) or len(channels) != count:
            raise ValueError(
                f"skeleton of {count} joints needs parents ({count},), offsets ({count}, 3) and {count} "
                f"channel lists; got {parents.shape}, {offsets.shape}, {len(channels)}"
            )
        if len(set(names)) != count:
            raise ValueError("joint names must be unique")
        for name in names:
            # What the reader can produce: words joined by single spaces, no lone brace.
            words = name.split()
            if not words or name != " ".join(words) or "{" in words or "}" in words:
                raise ValueError(f"invalid joint name {name!r}")
        _check_depth_first(parents)
        if not np.isfinite(offsets).all():
            raise ValueError("offsets must be finite")
        for j, cs in enumerate(channels):
            unknown = [c for c in cs if c not in CHANNEL_NAMES]
            if unknown or len(set(cs)) != len(cs):
                raise ValueError(f"invalid channels {cs} for joint {names[j]!r}")
        for parent, offset in end_sites:
            if not 0 <= parent < count:
                raise ValueError(f"End Site parent {parent} is not a joint index")
            if offset is not None and (offset.shape != (3,) or not np.isfinite(offset).all()):
                raise ValueError("End Site offsets must be 3 finite numbers")
        for field, value in (("names", names), ("parents", parents), ("offsets", offsets),
                             ("channels", channels), ("end_sites", end_sites)):
            object.__setattr__(self, field, value)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Skeleton):
            return NotImplemented
        return (
            self.same_hierarchy(other)
            and np.array_equal(self.offsets, other.offsets)
            and self.channels == other.channels
            and len(self.end_sites) == len(other.end_sites)
            and all(
                p == q and (o is None if r is None else (o is not None and np.array_equal(o, r)))
                for (p, o), (q, r) in zip(self.end_sites, other.end_sites)
            )
        )

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_channels(self) -> int:
        return sum(len(cs) for cs in self.channels)

    @property
    def channel_starts(self) -> np.ndarray:
        """Start column of each joint's channels in a frame row."""
        counts = np.array([len(cs) for cs in self.channels], dtype=np.int64)
        return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if len(counts) else counts

    def rotation_order(self, joint: int) -> str:
        """Axes of the joint's rotation channels as written, e.g. "ZYX"; "" if none."""
        return "".join(c[0] for c in self.channels[joint] if c.endswith("rotation"))

    def position_channels(self, joint: int) -> tuple[str, ...]:
        """Axes that have a position channel, e.g. ("X", "Y", "Z") or ()."""
        return tuple(c[0] for c in self.channels[joint] if c.endswith("position"))

    def children(self, joint: int) -> list[int]:
        return [int(j) for j in np.flatnonzero(self.parents == joint)]

    @property
    def roots(self) -> list[int]:
        return [int(j) for j in np.flatnonzero(self.parents == -1)]

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise SinMDMError(f"unknown joint {name!r}; the skeleton has {_name_list(self.names)}") from None

    def same_hierarchy(self, other: Skeleton) -> bool:
        return self.names == other.names and np.array_equal(self.parents, other.parents)


@dataclass(frozen=True, eq=False)
class BVH:
    skeleton: Skeleton
    frame_time: float  # seconds
    values: np.ndarray  # float64 (frames, num_channels), rotations in degrees
    path: str | None = None

    def __post_init__(self) -> None:
        frame_time = float(self.frame_time)
        values = _frozen_array(self.values, np.float64)
        if not (np.isfinite(frame_time) and frame_time > 0):
            raise ValueError(f"frame time must be a finite number > 0, got {frame_time}")
        if values.ndim != 2 or values.shape[1] != self.skeleton.num_channels:
            raise ValueError(f"values must have shape (frames, {self.skeleton.num_channels}), got {values.shape}")
        object.__setattr__(self, "frame_time", frame_time)
        object.__setattr__(self, "values", values)
        if self.path is not None:
            object.__setattr__(self, "path", str(self.path))

    def __eq__(self, other: object) -> bool:
        """Same skeleton, frame time and values; the path is not compared."""
        if not isinstance(other, BVH):
            return NotImplemented
        return (
            self.skeleton == other.skeleton
            and self.frame_time == other.frame_time
            and np.array_equal(self.values, other.values)
        )

    @property
    def frames(self) -> int:
        return self.values.shape[0]

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time


def _frozen_array(value, dtype) -> np.ndarray:
    array = np.array(value, dtype=dtype)  # a copy, so freezing never touches the caller's array
    array.flags.writeable = False
    return array


def _check_depth_first(parents: np.ndarray) -> None:
    """Joints must be listed in file (depth-first) order: each joint's parent
    is the previous joint or one of its ancestors."""
    chain: list[int] = []  # ancestors of the previous joint, and itself
    for j, parent in enumerate(parents.tolist()):
        while chain and chain[-1] != parent:
            chain.pop()
        if parent != -1 and not chain:
            raise ValueError(f"joint {j} (parent {parent}) is not in depth-first file order")
        chain.append(j)


def _name_list(names: tuple[str, ...], limit: int = 8) -> str:
    shown = ", ".join(repr(n) for n in names[:limit])
    return shown + (f", ... ({len(names)} joints)" if len(names) > limit else "")


# --------------------------------------------------------------------------- reading


def read_bvh(path: str | os.PathLike) -> BVH:
    name = os.fspath(path)
    try:
        data = _read_regular_file(name)
    except OSError as exc:
        raise SinMDMError(f"cannot read {name}: {exc.strerror or exc}") from None
    return parse_bvh(data, name)


def _read_regular_file(name: str) -> bytes:
    """The bytes of a regular file of at most MAX_FILE_BYTES. Opened non-blocking, so a
    FIFO is refused instead of waiting forever for a writer."""
    with open(os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)), "rb") as fh:
        info = os.fstat(fh.fileno())
        if stat.S_ISDIR(info.st_mode):
            raise SinMDMError(f"cannot read {name}: it is a directory")
        if not stat.S_ISREG(info.st_mode):
            raise SinMDMError(f"cannot read {name}: not a regular file (a pipe, device or socket)")
        # st_size first, so a huge file is refused unread; the bounded read catches a growing one.
        if info.st_size > MAX_FILE_BYTES or len(data := fh.read(MAX_FILE_BYTES + 1)) > MAX_FILE_BYTES:
            raise SinMDMError(f"cannot read {name}: larger than the {MAX_FILE_BYTES >> 30} GiB a BVH file may have")
    return data


def parse_bvh(data: str | bytes, path: str = "<string>") -> BVH:
    """Parse BVH text; `path` names the source in errors (and is stored unless
    it is the "<string>" placeholder)."""
    path = str(path)
    text = _decode(data, path)
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    tokens, motion_index = _hierarchy_tokens(lines)
    skeleton = _parse_hierarchy(tokens, motion_index, path)
    frames, frame_time, data_index = _parse_motion_header(lines, motion_index, path)
    values = _parse_values(lines, data_index, frames, skeleton, path)
    return BVH(skeleton, frame_time, values, None if path == "<string>" else path)


def _decode(data: str | bytes, path: str) -> str:
    if isinstance(data, str):
        text = data
    else:
        raw = bytes(data)
        if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
            try:
                text = raw.decode("utf-16")
            except UnicodeDecodeError:
                raise BVHError(path, 1, "not a text file (binary data)") from None
        else:
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError:
                text = raw.decode("latin-1")
    text = text.removeprefix("\ufeff")
    if not text:
        raise BVHError(path, 1, "file is empty")
    if _looks_binary(text):
        raise BVHError(path, 1, "not a text file (binary data)")
    if not text.strip():
        raise BVHError(path, 1, "file is empty (only whitespace)")
    return text


def _looks_binary(text: str) -> bool:
    if "\x00" in text:
        return True
    sample = text[:8192]
    controls = sum(1 for ch in sample if (ord(ch) < 32 and ch not in "\t\n\r\f\v") or 0x7F <= ord(ch) <= 0x9F)
    return controls * 100 > len(sample)


def _hierarchy_tokens(lines: list[str]) -> tuple[list[tuple[int, str]], int | None]:
    """(line number, token) of everything before the line starting with MOTION,
    and the index of that line (None when there is none)."""
    tokens: list[tuple[int, str]] = []
    for index, line in enumerate(lines):
        words = line.split()
        if words and words[0].upper() == "MOTION":
            return tokens, index
        tokens.extend((index + 1, word) for word in words)
    return tokens, None


def _quote(token: str, limit: int = 40) -> str:
    return repr(token if len(token) <= limit else token[:limit] + "...")


def _parse_hierarchy(tokens: list[tuple[int, str]], motion_index: int | None, path: str) -> Skeleton:
    """Parse the hierarchy tokens without recursion: a stack holds the open blocks."""

    def fail(line: int, message: str) -> BVHError:
        return BVHError(path, line, message)

    def same_line_words(start: int) -> list[str]:
        """Tokens after `start` on its line, up to a brace or keyword."""
        line, words, i = tokens[start][0], [], start + 1
        while i < len(tokens) and tokens[i][0] == line and tokens[i][1].upper() not in _KEYWORDS:
            words.append(tokens[i][1])
            i += 1
        return words

    if not tokens:
        first = motion_index + 1 if motion_index is not None else 1
        raise fail(first, "expected 'HIERARCHY' at start of file, got 'MOTION'")
    if tokens[0][1].upper() != "HIERARCHY":
        raise fail(tokens[0][0], f"expected 'HIERARCHY' at start of file, got {_quote(tokens[0][1])}")

    names: list[str] = []
    name_lines: dict[str, int] = {}
    parents: list[int] = []
    offsets: list[np.ndarray | None] = []
    channels: list[tuple[str, ...] | None] = []  # None: no CHANNELS line (yet)
    end_sites: list[tuple[int, np.ndarray | None]] = []
    # Open blocks: [kind "joint"/"end", joint index, has child joints]
    stack: list[list] = []

    def describe(block: list) -> str:
        name = names[block[1]]
        return f"joint {name!r}" if block[0] == "joint" else f"End Site of joint {name!r}"

    i = 1
    while i < len(tokens):
        line, token = tokens[i]
        word = token.upper()
        block = stack[-1] if stack else None

        if word in ("ROOT", "JOINT"):
            if word == "ROOT" and block is not None:
                raise fail(line, f"ROOT inside {describe(block)}: nested joints are written JOINT")
            if word == "JOINT" and block is None:
                raise fail(line, "JOINT outside ROOT: expected 'ROOT' or 'MOTION'")
            if block is not None and block[0] == "end":
                raise fail(line, f"End Site cannot have child joints (in {describe(block)})")
            name_words = []
            i += 1
            while i < len(tokens) and tokens[i][0] == line and tokens[i][1] not in ("{", "}"):
                name_words.append(tokens[i][1])
                i += 1
            if not name_words:
                raise fail(line, f"expected a name after {word}")
            name = " ".join(name_words)
            if i >= len(tokens) or tokens[i][1] != "{":
                where = tokens[i][0] if i < len(tokens) else line
                raise fail(where, f"expected '{{' after {word} name")
            if name in name_lines:
                raise fail(line, f"duplicate joint name {name!r} (first at line {name_lines[name]})")
            if len(names) >= MAX_JOINTS:
                raise fail(line, f"too many joints (the limit is {MAX_JOINTS})")
            if len(stack) >= MAX_DEPTH:
                raise fail(line, f"joints nested deeper than {MAX_DEPTH} levels")
            if block is not None:
                block[2] = True
            name_lines[name] = line
            names.append(name)
            parents.append(block[1] if block is not None else -1)
            offsets.append(None)
            channels.append(None)
            stack.append(["joint", len(names) - 1, False])
            i += 1

        elif word == "END":
            if block is None:
                raise fail(line, "End Site outside a joint: expected 'ROOT' or 'MOTION'")
            if block[0] == "end":
                raise fail(line, f"End Site cannot have child joints (in {describe(block)})")
            if i + 1 >= len(tokens) or tokens[i + 1][1].upper() != "SITE":
                raise fail(line, "expected 'Site' after 'End'")
            i += 2
            if i >= len(tokens) or tokens[i][1] != "{":
                raise fail(tokens[i][0] if i < len(tokens) else line, "expected '{' after End Site")
            if len(stack) >= MAX_DEPTH:
                raise fail(line, f"joints nested deeper than {MAX_DEPTH} levels")
            end_sites.append((block[1], None))
            stack.append(["end", block[1], False])
            i += 1

        elif word == "OFFSET":
            if block is None:
                raise fail(line, "OFFSET outside a joint: expected 'ROOT' or 'MOTION'")
            words = same_line_words(i)
            numbers = []
            for w in words:
                try:
                    numbers.append(float(w))
                except ValueError:
                    raise fail(line, f"non-numeric value {_quote(w)} in OFFSET") from None
            if len(numbers) != 3:
                raise fail(line, f"expected 3 numbers after OFFSET, got {len(numbers)}")
            offset = np.array(numbers)
            if not np.isfinite(offset).all():
                raise fail(line, "NaN or infinite value in OFFSET")
            if np.abs(offset).max() > FLOAT32_MAX:
                raise fail(line, f"OFFSET value beyond the float32 range (+-{FLOAT32_MAX:.1e})")
            if block[0] == "end":
                if end_sites[-1][1] is not None:
                    raise fail(line, f"second OFFSET in {describe(block)}")
                end_sites[-1] = (block[1], offset)
            else:
                if offsets[block[1]] is not None:
                    raise fail(line, f"second OFFSET in {describe(block)}")
                offsets[block[1]] = offset
            i += 1 + len(words)

        elif word == "CHANNELS":
            if block is None:
                raise fail(line, "CHANNELS outside a joint: expected 'ROOT' or 'MOTION'")
            if block[0] == "end":
                raise fail(line, f"End Site cannot have CHANNELS (in {describe(block)})")
            if channels[block[1]] is not None:
                raise fail(line, f"second CHANNELS line in {describe(block)}")
            if block[2]:
                raise fail(line, f"CHANNELS must come before the child joints of {describe(block)}")
            words = same_line_words(i)
            if not words or not _INTEGER.fullmatch(words[0]):
                got = _quote(words[0]) if words else "nothing"
                raise fail(line, f"expected the number of channels after CHANNELS, got {got}")
            declared, listed = int(words[0]), words[1:]
            if declared != len(listed):
                raise fail(line, f"CHANNELS declares {declared} channels but lists {len(listed)}")
            joint_channels: list[str] = []
            for w in listed:
                canonical = _CANONICAL_CHANNEL.get(w.lower())
                if canonical is None:
                    raise fail(line, f"unknown channel {_quote(w)} (expected one of {', '.join(CHANNEL_NAMES)})")
                if canonical in joint_channels:
                    raise fail(line, f"repeated channel {canonical!r} in {describe(block)}")
                joint_channels.append(canonical)
            channels[block[1]] = tuple(joint_channels)
            i += 1 + len(words)

        elif token == "}":
            if block is None:
                raise fail(line, "unmatched '}': no joint is open here")
            if block[0] == "joint" and offsets[block[1]] is None:
                raise fail(line, f"expected OFFSET in {describe(block)} before '}}'")
            stack.pop()
            i += 1

        elif token == "{":
            raise fail(line, "unexpected '{': a block opens only after ROOT, JOINT or End Site")

        else:
            if block is None:
                raise fail(line, f"expected 'ROOT' or 'MOTION', got {_quote(token)}")
            expected = "OFFSET or '}'" if block[0] == "end" else "OFFSET, CHANNELS, JOINT, End Site or '}'"
            raise fail(line, f"unexpected {_quote(token)} in {describe(stack[-1])}: expected {expected}")

    if stack:
        if motion_index is None:
            raise fail(tokens[-1][0], f"unexpected end of file inside hierarchy: expected '}}' to close {describe(stack[-1])}")
        raise fail(motion_index + 1, f"expected '}}' to close {describe(stack[-1])} before MOTION")
    if not names:
        where = motion_index + 1 if motion_index is not None else tokens[-1][0]
        raise fail(where, "no ROOT joint in HIERARCHY")
    if motion_index is None:
        raise fail(tokens[-1][0], "unexpected end of file: expected the MOTION section after the hierarchy")
    return Skeleton(
        names=tuple(names),
        parents=np.array(parents, dtype=np.int64),
        offsets=np.array(offsets, dtype=np.float64).reshape(-1, 3),
        channels=tuple(cs if cs is not None else () for cs in channels),
        end_sites=tuple(end_sites),
    )


def _parse_motion_header(lines: list[str], motion_index: int, path: str) -> tuple[int, float, int]:
    """(frame count, frame time, index of the first data line)."""
    extra = lines[motion_index].split()[1:]
    if extra:
        raise BVHError(path, motion_index + 1, f"unexpected {_quote(extra[0])} after MOTION")
    frames: int | None = None
    frame_time: float | None = None
    index = motion_index + 1
    while frames is None or frame_time is None:
        while index < len(lines) and not lines[index].strip():
            index += 1
        missing = "'Frames:'" if frames is None else "'Frame Time:'"
        if index >= len(lines):
            raise BVHError(path, _last_content_line(lines), f"unexpected end of file: expected a {missing} line")
        line_no, content = index + 1, lines[index].strip()
        if (match := _FRAMES_LINE.fullmatch(content)) and frames is None:
            value = match.group(1).strip()
            if not _INTEGER.fullmatch(value):
                raise BVHError(path, line_no, f"expected an integer frame count after 'Frames:', got {_quote(value)}")
            frames = int(value)
            if frames < 0:
                raise BVHError(path, line_no, f"frame count must be >= 0, got {frames}")
        elif (match := _FRAME_TIME_LINE.fullmatch(content)) and frame_time is None:
            value = match.group(1).strip()
            try:
                frame_time = float(value)
            except ValueError:
                raise BVHError(path, line_no, f"expected a number after 'Frame Time:', got {_quote(value)}") from None
            if not np.isfinite(frame_time):
                raise BVHError(path, line_no, "NaN or infinite value in Frame Time")
            if frame_time <= 0:
                raise BVHError(path, line_no, f"frame time must be > 0, got {value}")
            if not MIN_FRAME_TIME <= frame_time <= MAX_FRAME_TIME:
                raise BVHError(
                    path, line_no,
                    f"frame time {value} s is outside {MIN_FRAME_TIME:g} .. {MAX_FRAME_TIME:g} s "
                    f"({1 / MAX_FRAME_TIME:g} .. {1 / MIN_FRAME_TIME:g} fps)",
                )
        else:
            raise BVHError(path, line_no, f"expected a {missing} line after MOTION, got {_quote(content)}")
        index += 1
    return frames, frame_time, index


def _check_frame_count(lines: list[str], data_index: int, frames: int, skeleton: Skeleton, path: str) -> None:
    """Refuse a declared frame count the memory bound or the file itself cannot back."""
    frames_line = _frames_line(lines, data_index)
    if frames * skeleton.num_joints > MAX_JOINT_FRAMES:
        raise BVHError(
            path, frames_line,
            f"{frames} frames of {skeleton.num_joints} joints is more than the {MAX_JOINT_FRAMES:,} "
            "joint-frames a clip may have",
        )
    # Without channels a frame is an empty line: the file must still have one per frame.
    if skeleton.num_channels == 0 and frames > len(lines) - data_index:
        raise BVHError(
            path, frames_line, f"declared {frames} frames but the file has {len(lines) - data_index} lines of motion"
        )


def _last_content_line(lines: list[str]) -> int:
    for index in range(len(lines) - 1, -1, -1):
        if lines[index].strip():
            return index + 1
    return 1


def _parse_values(lines: list[str], data_index: int, frames: int, skeleton: Skeleton, path: str) -> np.ndarray:
    channels = skeleton.num_channels
    data_lines = lines[data_index:]
    tokens = "\n".join(data_lines).split()
    try:
        flat = np.array(tokens, dtype=np.float64)
    except ValueError:
        raise _first_non_numeric(data_lines, data_index, path) from None

    def line_of(token_index: int) -> int:
        counts = np.cumsum([len(line.split()) for line in data_lines])
        return data_index + 1 + int(np.searchsorted(counts, token_index, side="right"))

    finite = np.isfinite(flat)
    if not finite.all():
        bad = int(np.argmin(finite))
        raise BVHError(path, line_of(bad), f"NaN or infinite value {_quote(tokens[bad])}")
    in_range = np.abs(flat) <= FLOAT32_MAX
    if not in_range.all():
        bad = int(np.argmin(in_range))
        raise BVHError(path, line_of(bad), f"value {_quote(tokens[bad])} is beyond the float32 range (+-{FLOAT32_MAX:.1e})")
    frames_line = _frames_line(lines, data_index)
    expected = frames * channels
    if flat.size > expected:
        if channels == 0:
            message = "the skeleton has no channels, but the motion section has values"
        else:
            message = f"too many values: declared {frames} frames (line {frames_line}), extra data starts here"
        raise BVHError(path, line_of(expected), message)
    if flat.size < expected:
        full, partial = divmod(flat.size, channels)
        if flat.size == 0:
            raise BVHError(path, frames_line, f"declared {frames} frames but the file has no motion values")
        if partial:
            raise BVHError(
                path,
                line_of(flat.size - 1),
                f"data ends inside frame {full + 1} ({partial} of {channels} values); "
                f"declared {frames} frames (line {frames_line})",
            )
        raise BVHError(
            path,
            frames_line,
            f"declared {frames} frames but found {full} full frames (data ends at line {line_of(flat.size - 1)})",
        )
    _check_frame_count(lines, data_index, frames, skeleton, path)
    return flat.reshape(frames, channels)


def _frames_line(lines: list[str], data_index: int) -> int:
    """Line number of the 'Frames:' header (it is one of the two header lines before the data)."""
    for index in range(data_index - 1, -1, -1):
        if _FRAMES_LINE.fullmatch(lines[index].strip()):
            return index + 1
    return data_index


def _first_non_numeric(data_lines: list[str], data_index: int, path: str) -> BVHError:
    for offset, line in enumerate(data_lines):
        for word in line.split():
            try:
                np.float64(word)
            except ValueError:
                return BVHError(path, data_index + offset + 1, f"non-numeric value {_quote(word)}")
    return BVHError(path, data_index + 1, "non-numeric value in the motion data")


# --------------------------------------------------------------------------- writing


MOTION_LINES_PER_CHUNK = 1024  # frames formatted at a time: a long motion's text is streamed, not held


def format_bvh(bvh: BVH, precision: int = 6, unwrap: bool = True) -> str:
    """BVH text: tab indentation, '\\n' line ends, values with `precision` decimals.

    With `unwrap`, every rotation curve is unwrapped over time (period 360), so
    the file has no 360-degree jumps; the rotations are the same."""
    return "".join(bvh_text_chunks(bvh, precision, unwrap))


def bvh_text_chunks(bvh: BVH, precision: int = 6, unwrap: bool = True) -> Iterator[str]:
    """format_bvh's text in pieces (the hierarchy, then MOTION_LINES_PER_CHUNK frames at a
    time); the values are checked before the first piece."""
    if not 0 <= precision <= 17:
        raise ValueError(f"precision must be between 0 and 17, got {precision}")
    skeleton = bvh.skeleton
    values = np.array(bvh.values, dtype=np.float64)
    if not np.isfinite(values).all():
        raise ValueError("cannot write a BVH with NaN or infinite values")
    if unwrap and values.shape[0] > 1:
        rotation = _rotation_columns(skeleton)
        for first in range(0, len(rotation), 16):  # a few curves at a time: np.unwrap's temporaries stay small
            columns = rotation[first : first + 16]
            values[:, columns] = np.unwrap(values[:, columns], period=360.0, axis=0)
    return _text_chunks(bvh, values, precision)


def _text_chunks(bvh: BVH, values: np.ndarray, precision: int) -> Iterator[str]:
    out = io.StringIO()
    out.write("HIERARCHY\n")
    _write_hierarchy(out, bvh.skeleton)
    out.write(f"MOTION\nFrames: {bvh.frames}\nFrame Time: {_exact(bvh.frame_time)}\n")
    yield out.getvalue()
    if values.size:
        row = " ".join([f"%.{precision}f"] * values.shape[1])
        for start in range(0, len(values), MOTION_LINES_PER_CHUNK):
            # Rounding first and adding 0.0 turns -0.0 into 0.0, so no "-0.000000".
            rounded = np.round(values[start : start + MOTION_LINES_PER_CHUNK], precision) + 0.0
            yield "".join([row % tuple(r) + "\n" for r in rounded.tolist()])
    elif bvh.frames:
        yield "\n" * bvh.frames


def write_bvh(path: str | os.PathLike, bvh: BVH, precision: int = 6, unwrap: bool = True) -> None:
    write_chunks_atomic(path, bvh_text_chunks(bvh, precision=precision, unwrap=unwrap))


def _rotation_columns(skeleton: Skeleton) -> list[int]:
    columns = [c for cs in skeleton.channels for c in cs]
    return [i for i, c in enumerate(columns) if c.endswith("rotation")]


def _exact(x: float) -> str:
    """Shortest positional decimal that reads back as the same float."""
    return np.format_float_positional(float(x), trim="-")


def _write_hierarchy(out: io.StringIO, skeleton: Skeleton) -> None:
    """Joints are in depth-first order, so a stack of open joints replays the
    nesting. Each End Site is written as soon as its joint is the innermost open
    block and the End Sites before it are written: this keeps their file order."""
    end_sites = skeleton.end_sites
    written = [False] * len(end_sites)
    next_end = 0
    open_joints: list[int] = []

    def write_end_site(k: int) -> None:
        tabs = "\t" * len(open_joints)
        offset = end_sites[k][1]
        out.write(f"{tabs}End Site\n{tabs}{{\n")
        if offset is not None:
            out.write(f"{tabs}\tOFFSET {' '.join(_exact(v) for v in offset)}\n")
        out.write(f"{tabs}}}\n")
        written[k] = True

    def write_due_end_sites() -> None:
        nonlocal next_end
        while next_end < len(end_sites) and (written[next_end] or (open_joints and end_sites[next_end][0] == open_joints[-1])):
            if not written[next_end]:
                write_end_site(next_end)
            next_end += 1

    def close_joint() -> None:
        joint = open_joints[-1]
        # End Sites listed out of file order still go inside their joint.
        for k, (parent, _) in enumerate(end_sites):
            if parent == joint and not written[k]:
                write_end_site(k)
        open_joints.pop()
        out.write("\t" * len(open_joints) + "}\n")
        write_due_end_sites()

    for j, name in enumerate(skeleton.names):
        parent = int(skeleton.parents[j])
        while open_joints and open_joints[-1] != parent:
            close_joint()
        tabs = "\t" * len(open_joints)
        keyword = "ROOT" if parent == -1 else "JOINT"
        out.write(f"{tabs}{keyword} {name}\n{tabs}{{\n")
        out.write(f"{tabs}\tOFFSET {' '.join(_exact(v) for v in skeleton.offsets[j])}\n")
        cs = skeleton.channels[j]
        out.write(f"{tabs}\tCHANNELS {len(cs)}{''.join(' ' + c for c in cs)}\n")
        open_joints.append(j)
        write_due_end_sites()
    while open_joints:
        close_joint()
