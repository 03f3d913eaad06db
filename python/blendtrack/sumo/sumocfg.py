"""SUMO configuration files as SUMO itself reads them, and the run's copy.

- :func:`read_xml` parses any SUMO XML input, gzipped or not (SUMO detects
  gzip by content, not by name, and so does this).
- :func:`is_config` tells a SUMO configuration from other XML, whatever the
  file is called (``.sumocfg``, ``.cfg``, ``.xml``): its root element is
  ``<configuration>`` or ``<sumoConfiguration>``.
- :class:`SumoConfig` reads the options a configuration sets and the files
  it names, relative to the configuration's folder as SUMO resolves them.
- :meth:`SumoConfig.write_run_config` writes the configuration a run
  actually starts SUMO with, into the run's own output folder: every input
  by absolute path, every output the scenario configures (``<output>``
  options, logs, detector and edge-data files of additional files) under
  that folder, with the folders it names created. The scenario's folder is
  never written, and two runs of one scenario share no file.
"""

from __future__ import annotations

import gzip
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import IO

from blendtrack import BlendtrackError


class ScenarioError(BlendtrackError, ValueError):
    """A scenario that cannot be run (missing, malformed, rejected by SUMO)."""


CONFIG_ROOTS = ("configuration", "sumoConfiguration")

#: Options naming files SUMO writes, besides every ``*-output`` option.
_OUTPUT_OPTIONS = {
    "log", "message-log", "error-log", "log-file", "netstate-dump", "save-state.files",
    "device.ssm.file", "save-configuration",
}

#: Elements of additional files whose ``file`` (or ``output``/``dest``)
#: attribute is a file SUMO writes; ``file`` elsewhere (rerouters, variable
#: speed signs) is an input.
_OUTPUT_ELEMENTS = {
    "e1Detector", "inductionLoop", "instantInductionLoop", "e2Detector", "laneAreaDetector",
    "e3Detector", "entryExitDetector", "edgeData", "laneData", "edgeRelations", "tazRelations",
    "routeProbe", "vTypeProbe", "timedEvent", "calibrator", "routeCalibrator", "overheadWireSegment",
}
_OUTPUT_ATTRIBUTES = ("file", "output", "dest")
_XSI = "{http://www.w3.org/2001/XMLSchema-instance}"


def _open(file: Path) -> IO[bytes]:
    """``file`` for reading, gunzipped when its content is gzip (as SUMO decides)."""
    with open(file, "rb") as f:
        gz = f.read(2) == b"\x1f\x8b"
    return gzip.open(file, "rb") if gz else open(file, "rb")  # type: ignore[return-value]


def read_xml(file: Path) -> ET.Element:
    """The root element of a SUMO XML file, gzipped or plain; a
    :class:`ScenarioError` naming the file when it cannot be read."""
    try:
        with _open(file) as stream:
            return ET.parse(stream).getroot()
    except ET.ParseError as e:
        raise ScenarioError(f"{file}: malformed XML: {e}") from None
    except (OSError, EOFError) as e:
        raise ScenarioError(f"{file}: cannot read: {e}") from None


def iter_xml(file: Path, tags: set[str]) -> "list[ET.Element]":
    """Elements named in ``tags`` anywhere in ``file`` (gzip or plain),
    read incrementally so large route files stay cheap."""
    found: list[ET.Element] = []
    try:
        with _open(file) as stream:
            depth_keep = 0
            for event, el in ET.iterparse(stream, events=("start", "end")):
                if event == "start":
                    if el.tag in tags:
                        depth_keep += 1
                    continue
                if el.tag in tags:
                    depth_keep -= 1
                    found.append(el)
                elif depth_keep == 0:
                    el.clear()
    except ET.ParseError as e:
        raise ScenarioError(f"{file}: malformed XML: {e}") from None
    except (OSError, EOFError) as e:
        raise ScenarioError(f"{file}: cannot read: {e}") from None
    return found


def mentions(file: Path, needle: bytes) -> bool:
    """Does ``file`` (gzip or plain) hold the bytes ``needle`` anywhere? A
    scan with no XML parse (a route file of 1.7 MB: milliseconds, where
    parsing it takes a quarter of a second); True when it cannot be read,
    so that the parse that follows says why."""
    keep = len(needle) - 1
    try:
        with _open(file) as stream:
            tail = b""
            while chunk := stream.read(1 << 20):
                # The end of the chunk before, for a needle across the boundary.
                buf = tail + chunk
                if needle in buf:
                    return True
                tail = buf[len(buf) - keep :]
    except (OSError, EOFError):
        return True
    return False


def is_config(file: Path) -> bool:
    """Whether ``file`` is a SUMO configuration, by its root element (read
    alone: a large network file is not parsed for this)."""
    try:
        with _open(file) as stream:
            for _, el in ET.iterparse(stream, events=("start",)):
                return el.tag in CONFIG_ROOTS
    except (ET.ParseError, OSError, EOFError):
        return False
    return False


def sumo_seconds(text: str) -> float:
    """A time as SUMO reads one (``value="15:0:0"`` in a configuration,
    ``--begin 54000``): seconds, ``H:M:S`` or ``D:H:M:S``; a ``ValueError``
    for anything else."""
    parts = text.strip().split(":")
    if len(parts) == 1:
        return float(parts[0])
    if len(parts) not in (3, 4):
        raise ValueError(f"{text!r} is not a time (seconds, H:M:S or D:H:M:S)")
    seconds = 0.0
    for part, unit in zip(reversed(parts), (1.0, 60.0, 3600.0, 86400.0)):
        seconds += float(part) * unit
    return seconds


def _split(value: str) -> list[str]:
    return [x for x in value.replace(",", " ").split() if x]


def _is_output(name: str) -> bool:
    return name in _OUTPUT_OPTIONS or name.endswith("-output")


class SumoConfig:
    """A SUMO configuration file: its options, and the files it names."""

    def __init__(self, file: Path):
        self.file = Path(file)
        # SUMO resolves relative paths against the folder of the file as
        # given (a symlink's folder, not its target's).
        self.folder = self.file.absolute().parent
        self.root = read_xml(self.file)
        if self.root.tag not in CONFIG_ROOTS:
            raise ScenarioError(
                f"{self.file}: not a SUMO configuration (root element <{self.root.tag}>, expected <configuration>)"
            )

    def _options(self) -> "list[tuple[str, ET.Element]]":
        """(section, option element) for every option; SUMO also accepts
        options directly under the root."""
        out: list[tuple[str, ET.Element]] = []
        for el in self.root:
            if not isinstance(el.tag, str):
                continue
            if el.get("value") is not None and len(el) == 0:
                out.append(("", el))
            for opt in el:
                if isinstance(opt.tag, str) and opt.get("value") is not None:
                    out.append((el.tag, opt))
        return out

    def option(self, name: str) -> str | None:
        for _, el in self._options():
            if el.tag == name:
                return el.get("value")
        return None

    def files(self, name: str) -> list[Path]:
        """The files an option names (comma or space separated), resolved
        as SUMO does; a :class:`ScenarioError` for one that does not exist."""
        value = self.option(name) or ""
        out = []
        for item in _split(value):
            p = Path(item) if os.path.isabs(item) else self.folder / item
            if not p.is_file():
                raise ScenarioError(f"{self.file}: {name} {item!r} does not exist")
            out.append(p.absolute())
        return out

    def write_run_config(self, out_dir: Path, name: str = "run.sumocfg") -> Path:
        """Writes the configuration a run starts SUMO with into ``out_dir``
        (created) and returns its path: inputs by absolute path, outputs
        under ``out_dir`` (an absolute output path keeps its file name
        only), additional files that write outputs rewritten into
        ``out_dir/additional/`` with their outputs under ``out_dir``."""
        out_dir = Path(out_dir).absolute()
        out_dir.mkdir(parents=True, exist_ok=True)
        extra = {"additional-files": [_run_additional(p, out_dir) for p in self.files("additional-files")]}
        return self._write(out_dir / name, out_dir, extra)

    def write_copy(self, target: Path, replace: dict[str, list[Path]]) -> Path:
        """Writes a copy of this configuration to ``target`` with every input
        by absolute path and the file lists of ``replace`` (option name ->
        files) in place of its own; outputs are left as they are (relative
        ones then land beside the copy, or under a run's folder once
        :meth:`write_run_config` is applied to it)."""
        target = Path(target).absolute()
        target.parent.mkdir(parents=True, exist_ok=True)
        return self._write(target, None, replace)

    def _write(self, target: Path, out_dir: Path | None, replace: dict[str, list[Path]]) -> Path:
        root = ET.Element("configuration")
        sections: dict[str, ET.Element] = {}
        for section, el in self._options():
            value = el.get("value") or ""
            if el.tag in replace:
                value = ",".join(str(p) for p in replace[el.tag])
            elif _is_output(el.tag):
                if out_dir is not None:
                    value = ",".join(str(_redirect(item, out_dir)) for item in _split(value))
            else:
                value = self._absolute_inputs(value)
            if not section:
                parent = root
            elif section in sections:
                parent = sections[section]
            else:
                parent = sections[section] = ET.SubElement(root, section)
            ET.SubElement(parent, el.tag, {"value": value})
        ET.ElementTree(root).write(target, encoding="utf-8", xml_declaration=True)
        return target

    def _absolute_inputs(self, value: str) -> str:
        """A value whose items all name existing files relative to the
        configuration's folder, with those made absolute; others as they are."""
        items = _split(value)
        if not items or any(os.path.isabs(i) or not (self.folder / i).exists() for i in items):
            return value
        return ",".join(str((self.folder / i).absolute()) for i in items)


def _redirect(item: str, out_dir: Path) -> Path:
    """Where an output the scenario configures goes: its relative path
    under ``out_dir`` (folders created), or ``out_dir/NAME`` for an
    absolute path or one that climbs out of the folder."""
    rel = Path(item)
    if rel.is_absolute() or ".." in rel.parts:
        rel = Path(rel.name)
    target = out_dir / rel
    target.parent.mkdir(parents=True, exist_ok=True)
    return target


def _run_additional(file: Path, out_dir: Path) -> Path:
    """The additional file a run loads: ``file`` itself when it writes
    nothing, else a copy in ``out_dir/additional/`` whose outputs go under
    ``out_dir`` and whose relative inputs point back to ``file``'s folder."""
    root = read_xml(file)
    writes = any(el.tag in _OUTPUT_ELEMENTS and any(el.get(a) for a in _OUTPUT_ATTRIBUTES) for el in root.iter())
    if not writes:
        return file
    base = file.parent
    for el in root.iter():
        for attr in _OUTPUT_ATTRIBUTES + ("href",):
            v = el.get(attr)
            if not v:
                continue
            if el.tag in _OUTPUT_ELEMENTS and attr in _OUTPUT_ATTRIBUTES:
                el.set(attr, str(_redirect(v, out_dir)))
            elif not os.path.isabs(v) and (base / v).exists():
                el.set(attr, str((base / v).absolute()))
    for key in list(root.attrib):
        if key.startswith(_XSI):
            del root.attrib[key]
    dest_dir = out_dir / "additional"
    dest_dir.mkdir(parents=True, exist_ok=True)
    stem = file.name[:-3] if file.name.endswith(".gz") else file.name
    dest = dest_dir / stem
    n = 1
    while dest.exists():
        dest = dest_dir / f"{n}_{stem}"
        n += 1
    ET.ElementTree(root).write(dest, encoding="utf-8", xml_declaration=True)
    return dest
