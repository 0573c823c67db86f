"""Reading Miro's XML configuration format into plain data, with source lines.

Reading never validates and validation never touches the file (the pydantic-settings
habit): :func:`read_document` turns the XML into :class:`Section` / :class:`ParameterSet`
objects holding plain ``str`` / ``dict`` / ``list`` values plus the line of every value,
and :mod:`afa.config.loader` validates them against parameter models.

Format (``docs/configuration.md``; Miro's ``ConfigDocument.cpp``)::

    <config>
      <section name="SECTION">
        <parameter name="NS::TypeParameters"> fields </parameter>        default set
        <instance name="NAME" type="NS::TypeParameters"> fields </instance>  named sets
      </section>
    </config>

A field is ``<parameter name="F" value="v"/>`` (scalar), ``<parameter name="F">`` with
named children (struct) or with unnamed children (vector of scalars or structs).

The parser is hardened: no DTD loading, no entity resolution, no network, no internal
DTD subset (so no entity-expansion attack), a size limit that holds for any kind of file
(at most limit + 1 bytes are read, from a pipe or ``/dev/zero`` too) and, for the
configuration, a limit on the number of elements, which bounds the validation work.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lxml import etree

from afa.errors import ConfigError

__all__ = ["read_document", "MiroDocument", "Section", "ParameterSet", "MAX_FILE_BYTES",
           "MAX_ELEMENTS", "read_bounded", "parse_xml"]

#: Configuration files larger than this are refused (the Raptor's is ~20 kB).
MAX_FILE_BYTES = 4 * 1024 * 1024
#: Elements in a configuration file, at most (the Raptor's has 400). Each may cost a
#: validation error with a spelling suggestion (~0.2 ms), so this bounds the work.
MAX_ELEMENTS = 10_000

Path_ = tuple[str | int, ...]


@dataclass
class ParameterSet:
    """One parameter set: the default set of a section or a named instance."""

    type_name: str
    instance: str  # "" for the section's default set
    line: int
    values: dict[str, Any] = field(default_factory=dict)
    lines: dict[Path_, int] = field(default_factory=dict)

    def line_of(self, loc: Path_) -> int:
        """The line of the deepest known prefix of ``loc``."""
        for cut in range(len(loc), 0, -1):
            line = self.lines.get(tuple(loc[:cut]))
            if line is not None:
                return line
        return self.line


@dataclass
class Section:
    name: str
    line: int
    default: ParameterSet | None = None
    instances: dict[str, ParameterSet] = field(default_factory=dict)


@dataclass
class MiroDocument:
    path: Path
    sections: dict[str, Section]


def read_bounded(path: Path, limit: int) -> bytes:
    """The bytes of ``path``, reading at most ``limit`` + 1 of them whatever the file is: a
    regular file, a pipe or FIFO (``--world <(generate)``), a device (``/dev/zero``). A
    FIFO blocks until a writer opens it, as with any reader.

    Raises :class:`~afa.errors.ConfigError` (``path:1``) if the file holds more than
    ``limit`` bytes; an :class:`OSError` is left to the caller, who knows what kind of
    file could not be read.
    """
    with open(path, "rb") as file:
        data = file.read(limit + 1)
        if len(data) > limit:
            status = os.fstat(file.fileno())
            size = (f"is {status.st_size} bytes" if stat.S_ISREG(status.st_mode)
                    else f"holds more than {limit} bytes")
            raise ConfigError(f"{path}:1: file {size}; the limit is {limit}")
    return data


_MISMATCH = re.compile(r"Opening and ending tag mismatch: (\S+) line (\d+) and (\S+?)"
                       r"(?:, line \d+, column \d+)?$")
_QUOTE_SCAN = 40  # lines searched back for an attribute value's opening quote
_INDENT_SCAN = 400  # lines searched for an element left open (quadratic in it at worst)


def _syntax_cause(exc: etree.XMLSyntaxError, data: bytes) -> tuple[int, str]:
    """The line that caused a syntax error, and the message to print there.

    The parser notices most mistakes later than they were made: an element left open
    (``/>`` written ``>``) at the end tag of its parent, a missing closing quote on the
    next line. Those are reported where they began."""
    where = exc.lineno or 1
    message = re.sub(r", line \d+, column \d+$", "", exc.msg or "")
    mismatch = _MISMATCH.match(exc.msg or "")
    if mismatch is not None:
        opened, line, closer = mismatch.group(1), int(mismatch.group(2)), mismatch.group(3)
        line = _left_open(data, opened, line, where)
        return line, (f"<{opened}> opened here is not closed where expected (</{closer}> "
                      f"at line {where} closes something else; is a '/>' missing here, or "
                      "an end tag extra?)")
    if "attributes values" in message or message.startswith("AttValue"):
        lines = data.split(b"\n")
        for number in range(min(where, len(lines)), max(0, where - _QUOTE_SCAN), -1):
            if lines[number - 1].count(b'"') % 2:  # (an apostrophe in a comment is no quote)
                if number != where:
                    return number, (f"an attribute value opened here is not closed "
                                    f"({message} at line {where})")
                break
    return where, message


def _left_open(data: bytes, tag: str, first: int, last: int) -> int:
    """Which ``<tag>`` between lines ``first`` and ``last`` was left open, judged by
    indentation: the first start tag (not ``/>``) whose next line at its own indentation
    or less is not its end tag at its own indentation (a less indented end tag is its
    parent's). The parser only knows that the one at ``first`` did not end where
    expected (an inner one left open took its end tag); ``first`` if the indentation
    does not tell."""
    if last - first > _INDENT_SCAN:
        return first  # bounded work on any file: a long stretch is not guessed at
    lines = data.decode("utf-8", "replace").split("\n")
    start = re.compile(rf"^(\s*)<{re.escape(tag)}\b[^<]*(?<!/)>\s*$")

    def indent(text: str) -> int:
        return len(text) - len(text.lstrip())

    for number in range(first, min(last, len(lines) + 1)):
        opened = start.match(lines[number - 1])
        if opened is None:
            continue
        for later in lines[number:last]:
            if later.strip() and indent(later) <= len(opened.group(1)):
                if (indent(later) < len(opened.group(1))
                        or not later.lstrip().startswith(f"</{tag}")):
                    return number
                break
    return first


def parse_xml(data: bytes, path: Path) -> etree._Element:
    """Parse XML hardened against hostile files: no DTD loading, no entity resolution,
    no network, no internal DTD subset (so no entity expansion), no entity references.
    Every XML file afa reads (configuration, geometry, worlds) goes through here.

    Raises :class:`~afa.errors.ConfigError` (``path:line: message``).
    """
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                             dtd_validation=False, huge_tree=False, remove_comments=True,
                             remove_pis=True)
    try:
        root = etree.fromstring(data, parser=parser)
    except etree.XMLSyntaxError as exc:
        line, message = _syntax_cause(exc, data)
        raise ConfigError(f"{path}:{line}: XML syntax error: {message}") from None
    if root.getroottree().docinfo.internalDTD is not None:
        raise ConfigError(f"{path}:1: a DTD internal subset is not allowed (entities and "
                          "entity expansion are refused)")
    for node in root.iter():
        if isinstance(node, etree._Entity):
            raise ConfigError(f"{path}:{node.sourceline}: entity references are not allowed")
    return root


def read_document(path: str | Path) -> MiroDocument:
    """Read a Miro configuration file into plain data.

    Raises :class:`~afa.errors.ConfigError` (``file:line: message``) for a missing,
    oversized or malformed file, a DTD subset or entity, or a structural error.
    """
    path = Path(path)
    try:
        data = read_bounded(path, MAX_FILE_BYTES)
    except OSError as exc:
        raise ConfigError(f"{path}:0: cannot read: {exc.strerror or exc}") from exc
    return parse_document(data, path)


def parse_document(data: bytes, path: Path) -> MiroDocument:
    """Parse configuration bytes (``path`` is used in messages)."""
    root = parse_xml(data, path)
    for count, node in enumerate(root.iter(), start=1):
        if count > MAX_ELEMENTS:
            raise ConfigError(f"{path}:{node.sourceline or 1}: more than {MAX_ELEMENTS} "
                              "elements (the limit; the Raptor's configuration has 400)")
    if root.tag != "config":
        raise ConfigError(f"{path}:{root.sourceline}: the root element must be <config>, "
                          f"not <{root.tag}>")
    sections: dict[str, Section] = {}
    for element in root:
        if element.tag != "section":
            raise ConfigError(
                f"{path}:{element.sourceline}: expected <section>, got <{element.tag}>")
        name = _attribute(path, element, "name")
        if name in sections:
            raise ConfigError(f"{path}:{element.sourceline}: section {name!r} appears twice "
                              f"(first at line {sections[name].line})")
        sections[name] = _read_section(path, element, name)
    return MiroDocument(path, sections)


def _attribute(path: Path, element: etree._Element, name: str) -> str:
    value = element.get(name)
    if value is None:
        raise ConfigError(
            f"{path}:{element.sourceline}: <{element.tag}> needs a {name!r} attribute")
    return value


def _read_section(path: Path, element: etree._Element, name: str) -> Section:
    section = Section(name, element.sourceline or 0)
    for child in element:
        if child.tag == "parameter":
            if section.default is not None:
                raise ConfigError(f"{path}:{child.sourceline}: section {name!r} has two default "
                                  "parameter sets; use <instance> for named sets")
            pset = ParameterSet(_attribute(path, child, "name"), "", child.sourceline or 0)
            section.default = pset
        elif child.tag == "instance":
            instance = _attribute(path, child, "name")
            if instance in section.instances:
                raise ConfigError(f"{path}:{child.sourceline}: instance {instance!r} appears "
                                  f"twice in section {name!r}")
            pset = ParameterSet(_attribute(path, child, "type"), instance, child.sourceline or 0)
            section.instances[instance] = pset
        else:
            raise ConfigError(f"{path}:{child.sourceline}: expected <parameter> or <instance> "
                              f"in section {name!r}, got <{child.tag}>")
        pset.values = _read_struct(path, child, (), pset.lines)
    return section


def _read_struct(path: Path, element: etree._Element, prefix: Path_,
                 lines: dict[Path_, int]) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for child in element:
        if child.tag != "parameter":
            raise ConfigError(f"{path}:{child.sourceline}: expected <parameter>, got <{child.tag}>")
        name = child.get("name")
        if name is None:
            raise ConfigError(f"{path}:{child.sourceline}: a struct member needs a name")
        if name in values:
            raise ConfigError(f"{path}:{child.sourceline}: parameter {name!r} appears twice")
        lines[prefix + (name,)] = child.sourceline or 0
        values[name] = _read_value(path, child, prefix + (name,), lines)
    return values


def _read_value(path: Path, element: etree._Element, loc: Path_, lines: dict[Path_, int]) -> Any:
    value = element.get("value")
    children = list(element)
    if value is not None:
        if children:
            raise ConfigError(f"{path}:{element.sourceline}: a parameter has either a value "
                              "or children, not both")
        return value
    if not children:
        return []  # an empty vector (or an empty struct; the model decides)
    if all(c.get("name") is not None for c in children):
        return _read_struct(path, element, loc, lines)
    if any(c.get("name") is not None for c in children):
        raise ConfigError(f"{path}:{element.sourceline}: mixes named (struct) and unnamed "
                          "(vector) children")
    items = []
    for index, child in enumerate(children):
        if child.tag != "parameter":
            raise ConfigError(f"{path}:{child.sourceline}: expected <parameter>, got <{child.tag}>")
        lines[loc + (index,)] = child.sourceline or 0
        items.append(_read_value(path, child, loc + (index,), lines))
    return items
