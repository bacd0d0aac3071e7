"""Shared machinery of the input readers: bounded file reading, safe XML, number parsing."""

from __future__ import annotations

import contextlib
import gc
import json
import math
import os
import re
import stat
from collections.abc import Iterator
from dataclasses import dataclass
from xml.etree.ElementTree import ParseError

import numpy as np
from defusedxml import DefusedXmlException, ExternalReferenceForbidden
from defusedxml.ElementTree import DefusedXMLParser

from tagbot.errors import InputError
from tagbot.inputs.trace import Trace

MAX_INPUT_BYTES = 32 * 1024 * 1024
"""Largest input file tagbot reads (32 MB); larger files are refused before being read."""

MAX_MAGNITUDE = 1e15
"""Largest coordinate or time magnitude accepted (larger ones are refused or skipped), so that
differences and offsets of any two values stay finite."""

_MB = 1024 * 1024

_JSONP = re.compile(r"\s*[A-Za-z_$][\w$.]*\s*\((\s*[\[{].*)\)\s*;?\s*", re.DOTALL)

_NUMBER = re.compile(r"[+-]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][+-]?\d+)?")


def read_input(path: str | os.PathLike[str]) -> bytes:
    """Read a whole input file, refusing one larger than :data:`MAX_INPUT_BYTES`.

    Only regular files are read: a FIFO, socket or device is refused at once (opened without
    blocking, so a FIFO nobody writes to cannot hang the reader). The size is checked with
    ``fstat`` before reading and again while reading.
    """
    name = os.fsdecode(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except OSError as e:
        raise InputError(f"{name}: cannot read ({e.strerror or e})") from e
    try:
        with os.fdopen(fd, "rb") as f:
            info = os.fstat(f.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise InputError(f"{name}: not a regular file ({_kind(info.st_mode)})")
            if info.st_size > MAX_INPUT_BYTES:
                raise InputError(f"{name}: {_too_big(info.st_size)}")
            data = f.read(MAX_INPUT_BYTES + 1)
    except OSError as e:
        raise InputError(f"{name}: cannot read ({e.strerror or e})") from e
    if len(data) > MAX_INPUT_BYTES:
        raise InputError(f"{name}: {_too_big(None)}")
    return data


def _kind(mode: int) -> str:
    for test, kind in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return kind
    return "not a file"


def check_size(data: bytes, name: str) -> None:
    """Refuse in-memory input larger than :data:`MAX_INPUT_BYTES`."""
    if len(data) > MAX_INPUT_BYTES:
        raise InputError(f"{name}: {_too_big(len(data))}")


def _too_big(size: int | None) -> str:
    limit = f"the {MAX_INPUT_BYTES // _MB} MB limit"
    if size is None:
        return f"file is more than {limit}"
    return f"file is {math.ceil(size / _MB)} MB, more than {limit}"


def preview(data: bytes | str, limit: int = 12) -> str:
    """Quote the first word of ``data`` briefly for messages, e.g. ``'%PDF-1.4'``."""
    text = data[: limit * 4].decode("utf-8", "replace") if isinstance(data, bytes) else data
    words = text.lstrip("\ufeff \t\r\n").split(None, 1)
    word = words[0] if words else ""
    return repr(word[:limit] + ("..." if len(word) > limit else ""))


def cut(s: object, limit: int = 40) -> str:
    """Quote a value briefly for messages."""
    r = repr(s)
    return r if len(r) <= limit else r[: limit - 4] + "...'"


def parse_number(text: object, decimal_comma: bool = True) -> float | None:
    """Parse a finite decimal number written as text (or a JSON number); None if it is not one.

    Accepts a decimal comma (``"0,532"``) when ``decimal_comma`` is true; refuses ``nan``,
    ``inf``, booleans, hex and digit separators. The range is not checked (see
    :data:`MAX_MAGNITUDE`).
    """
    if type(text) is not str:
        if isinstance(text, bool) or not isinstance(text, int | float):
            return None
        try:
            x = float(text)
        except OverflowError:
            return None
        return x if math.isfinite(x) else None
    s = text.strip()
    if not _NUMBER.fullmatch(s) or ("," in s and not decimal_comma):
        return None
    x = float(s.replace(",", "."))
    return x if math.isfinite(x) else None


def number_problem(text: object, decimal_comma: bool = True) -> str | None:
    """What is wrong with a number that cannot be used: ``"not a finite number"`` (``NaN``,
    ``inf``, ``1e400``) or ``"out of range"`` (beyond :data:`MAX_MAGNITUDE`); None when ``text``
    is a usable number, or no number at all (readers that skip junk decide about that)."""
    if isinstance(text, bool):
        return None
    if isinstance(text, int | float):
        try:
            x = float(text)
        except OverflowError:
            return "out of range"
    elif isinstance(text, str):
        s = text.strip()
        if s.lower().lstrip("+-") in ("nan", "inf", "infinity"):
            return "not a finite number"
        if not _NUMBER.fullmatch(s) or ("," in s and not decimal_comma):
            return None
        x = float(s.replace(",", "."))
    else:
        return None
    if not math.isfinite(x):
        return "not a finite number"
    return "out of range" if abs(x) > MAX_MAGNITUDE else None


# --------------------------------------------------------------------------- XML


class Node:
    """An XML element (or a JSON object standing for one), names lower-cased, namespaces dropped."""

    __slots__ = ("attrs", "children", "closed", "name", "parts")

    def __init__(self, name: str, attrs: dict[str, str] | None = None) -> None:
        self.name = name
        self.attrs: dict[str, str] = attrs if attrs is not None else {}
        self.children: list[Node] = []
        self.parts: list[str] | None = []
        """Character data of a leaf element; None once the element has child elements."""
        self.closed = False
        """True once the element's end tag was read (False for elements cut by a truncation)."""

    @property
    def text(self) -> str:
        return "".join(self.parts) if self.parts else ""

    def child(self, name: str) -> Node | None:
        """The first child element called ``name``, if any."""
        for c in self.children:
            if c.name == name:
                return c
        return None

    def iter(self) -> Iterator[Node]:
        """All elements of the subtree in document order (iteratively: no recursion limit)."""
        stack = [self]
        while stack:
            node = stack.pop()
            yield node
            if node.children:
                stack.extend(reversed(node.children))


def local_name(tag: str) -> str:
    """``{namespace}Name`` → ``name``."""
    return tag.rpartition("}")[2].lower()


class _TreeTarget:
    """Builds :class:`Node` trees from parser events, keeping what was read before an error."""

    def __init__(self) -> None:
        self.root: Node | None = None
        self.stack: list[Node] = []
        self.names: dict[str, str] = {}

    def _name(self, tag: str) -> str:
        name = self.names.get(tag)
        if name is None:
            name = self.names[tag] = local_name(tag)
        return name

    def start(self, tag: str, attrib: dict[str, str]) -> None:
        node = Node(
            self._name(tag), {self._name(k): v for k, v in attrib.items()} if attrib else {}
        )
        stack = self.stack
        if stack:
            parent = stack[-1]
            parent.children.append(node)
            parent.parts = None
        elif self.root is None:
            self.root = node
        stack.append(node)

    def end(self, tag: str) -> None:
        self.stack.pop().closed = True

    def data(self, text: str) -> None:
        if self.stack:
            parts = self.stack[-1].parts
            if parts is not None:
                parts.append(text)

    def close(self) -> Node | None:
        return self.root


@dataclass
class XmlDocument:
    """The result of :func:`parse_xml`."""

    root: Node | None
    """The root element, None if the input ends before it."""
    truncated: str | None = None
    """Why the input ended early (e.g. ``unclosed token: line 40, column 3``), None if complete."""


@contextlib.contextmanager
def paused_gc() -> Iterator[None]:
    """Pause the cyclic garbage collector while building large acyclic trees.

    A 32 MB GML holds millions of elements; without this, repeated full collections scanning
    them take most of the reading time. Reference counting still frees everything.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def parse_xml(data: bytes | str, name: str) -> XmlDocument:
    """Parse untrusted XML into a :class:`Node` tree.

    Parsed with defusedxml: entity declarations (which billion-laughs and external-entity attacks
    need) are refused, and external references are never fetched. An input that ends early (cut
    off) returns what was complete before the cut with ``truncated`` set; a document that is
    malformed before its end raises InputError, except for junk after a complete root element,
    which is ignored.
    """
    with paused_gc():
        return _parse_xml(data, name)


def _parse_xml(data: bytes | str, name: str) -> XmlDocument:
    target = _TreeTarget()
    parser = DefusedXMLParser(target=target)
    try:
        parser.feed(data)
    except DefusedXmlException as e:
        raise InputError(f"{name}: {_refusal(e)}") from e
    except ParseError as e:
        if target.root is not None and target.root.closed:
            return XmlDocument(target.root)  # junk after the document element
        raise InputError(f"{name}: not well-formed XML ({e})") from e
    except (LookupError, ValueError, UnicodeError) as e:
        raise InputError(f"{name}: unreadable XML ({e})") from e
    try:
        parser.close()
    except DefusedXmlException as e:  # pragma: no cover - refused in feed() already
        raise InputError(f"{name}: {_refusal(e)}") from e
    except ParseError as e:
        return XmlDocument(target.root, truncated=str(e))
    except (LookupError, ValueError, UnicodeError) as e:
        raise InputError(f"{name}: unreadable XML ({e})") from e
    return XmlDocument(target.root)


def _refusal(e: DefusedXmlException) -> str:
    if isinstance(e, ExternalReferenceForbidden):
        return "XML external references are refused (untrusted input)"
    return "XML entity declarations are refused (untrusted input)"


# --------------------------------------------------------------------------- text and JSON


def decode_text(data: bytes, name: str, what: str) -> str:
    """Decode UTF-8 (with or without a byte-order mark); ``what`` names the format in errors."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"{name}: not a {what} (not UTF-8 text at byte {e.start})") from e


def unwrap_jsonp(text: str) -> str | None:
    """``callback({...});`` → ``{...}``; None if ``text`` is not JSONP."""
    first = text.lstrip()[:1]
    m = _JSONP.fullmatch(text) if first.isalpha() or (first and first in "_$") else None
    return m.group(1) if m else None


def parse_json(text: str, name: str) -> object:
    """Parse JSON, or JSONP ``callback(...)``; ``NaN`` and ``Infinity`` are refused."""
    try:
        inner = unwrap_jsonp(text)
        return json.loads(text if inner is None else inner, parse_constant=_refuse_constant)
    except json.JSONDecodeError as e:
        raise InputError(f"{name}: not JSON (line {e.lineno}, column {e.colno}: {e.msg})") from e
    except RecursionError as e:
        raise InputError(f"{name}: not JSON (nested too deeply)") from e
    except ValueError as e:  # NaN/Infinity, or an integer with too many digits
        raise InputError(f"{name}: not JSON ({e})") from e


def _refuse_constant(word: str) -> object:
    raise ValueError(f"{word} is not a finite number")


def json_to_node(name: str, value: object) -> Node:
    """Turn parsed JSON into a :class:`Node` tree, as #000000book's JSON mirrors GML's XML.

    An object's fields become child elements (a list becomes repeated elements of the same
    name, so a one-element list and a bare object read the same); scalars become text. Keys are
    lower-cased and a leading ``@`` (attribute marker of XML-to-JSON converters) is dropped.
    """
    with paused_gc():
        return _json_to_node(name, value)


def _json_to_node(name: str, value: object) -> Node:
    root = Node(local_name(name))
    stack: list[tuple[Node, object]] = [(root, value)]
    while stack:
        node, v = stack.pop()
        node.closed = True
        if isinstance(v, dict):
            node.parts = None
            for key, item in v.items():
                child_name = local_name(str(key)).lstrip("@")
                for it in item if isinstance(item, list) else [item]:
                    child = Node(child_name)
                    node.children.append(child)
                    stack.append((child, it))
        elif isinstance(v, list):
            node.parts = None  # a list inside a list has no element name: ignored
        elif isinstance(v, bool):
            node.parts = ["true" if v else "false"]
        elif v is not None:
            node.parts = [str(v)]
    return root


def make_trace(name: str, xy: np.ndarray, t: np.ndarray | None, clock: str | None = None) -> Trace:
    """A :class:`Trace`, its validation errors prefixed with the file's name; coordinates (in mm,
    after any conversion) must stay within :data:`MAX_MAGNITUDE`."""
    far = np.flatnonzero(~(np.abs(np.asarray(xy, dtype=float)) <= MAX_MAGNITUDE).all(axis=1))
    if far.size:
        raise InputError(
            f"{name}: point {int(far[0])} of a trace is beyond ±{MAX_MAGNITUDE:g} mm (or not"
            " finite) once converted"
        )
    try:
        return Trace(xy, t, clock)
    except InputError as e:  # pragma: no cover - readers check their values first
        raise InputError(f"{name}: {e}") from e
