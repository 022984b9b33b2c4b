"""The published ``solution.xdmf`` of ``io.SolutionWriter`` and its folder of HDF5 files (rank 0's side).

Layout, in the output folder::

    solution.xdmf              the meshes, then per field a temporal collection of output times
    solution.h5                the mesh (DOLFINx's XDMFFile opens it to read solution.xdmf)
    solution/mesh_<k>.h5       the mesh of the k-th resumed part of the run
    solution/<k:06d>.h5        the fields of the k-th output time (k from 0)

Kill-safety: a published file is never written again while ``solution.xdmf`` lists it. DOLFINx
writes each file under a hidden name (``.<k:06d>.h5``, with its XML in ``.<k:06d>.xdmf``, made
from a template that holds the mesh); once DOLFINx has closed it, the file is renamed into
place, and only then is ``solution.xdmf`` rewritten (a temporary file, then ``os.replace``). A
run killed at any moment leaves the times listed before intact (what a process wrote survives
its death); hidden files and files listed nowhere are what a killed writer left, removed when a
run resumes. A resumed writer first publishes ``solution.xdmf`` cut to the checkpoint's output
times, and only then rewrites the later files. ``sync`` (before every checkpoint) puts the files
on disk (fsync), so that a stopped machine keeps the output times its last checkpoint counts;
fsyncing every output time instead cost 0.5-1.5 ms each, 20 ms and more on a busy disk.

``Index`` holds ``solution.xdmf`` in memory; it runs on one process (rank 0), the writing of the
HDF5 files by DOLFINx being collective.
"""

from __future__ import annotations

import os
import pathlib
import re
import shutil
import xml.etree.ElementTree as ElementTree
from xml.sax.saxutils import quoteattr

from dolfinx_dem.errors import OutputError

XI = "http://www.w3.org/2001/XInclude"
FOLDER = "solution"
_HEADER = '<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n'

ElementTree.register_namespace("xi", XI)


def time_file(k: int) -> str:
    """The name of the k-th output time's HDF5 file in the folder (without the folder)."""
    return f"{k:06d}.h5"


def hidden(folder: pathlib.Path, name: str, suffix: str) -> pathlib.Path:
    """The hidden name under which DOLFINx writes the file ``name`` (its stem) with ``suffix``."""
    return folder / f".{pathlib.Path(name).stem}{suffix}"


def mesh_xpath(name: str) -> str:
    return f"/Xdmf/Domain/Grid[@Name='{name}'][1]"


def fsync(path: pathlib.Path) -> None:
    """Make the data of the file ``path``, or the entries of the folder ``path``, durable."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _dolfinx_xml(path: pathlib.Path) -> ElementTree.Element:
    """The XML DOLFINx wrote, made readable by VTK: the W3C XInclude namespace's ``http://`` name
    (DOLFINx 0.9 writes ``https://``, which VTK's XDMF reader, hence ParaView and pyvista, does not
    recognise: its meshless grids crash it), and a 1D displacement typed as what its data are:
    ``Vector`` when DOLFINx 0.9 pads it to three components (typed ``Scalar``, it would be read as
    three values per cell), ``Scalar`` when DOLFINx 0.5 writes its one component typed ``Vector``
    (VTK then warns at every read, "Can not set attribute Vectors", about 80 times per 1D
    animation)."""
    text = path.read_text().replace('xmlns:xi="https://www.w3.org/2001/XInclude"', f'xmlns:xi="{XI}"')
    padded = r'AttributeType="Scalar"(\s+Center="Cell">\s*<DataItem Dimensions="\d+ 3")'
    text = re.sub(padded, r'AttributeType="Vector"\1', text)
    one = r'AttributeType="Vector"(\s+Center="Cell">\s*<DataItem Dimensions="\d+ 1")'
    return ElementTree.fromstring(re.sub(one, r'AttributeType="Scalar"\1', text))


def _text(grid: ElementTree.Element, level: int) -> str:
    """The XML of ``grid`` at the depth ``level`` of the document, one line per element."""
    ElementTree.indent(grid, "  ", level)
    grid.tail = None
    text = ElementTree.tostring(grid, "unicode").replace(f' xmlns:xi="{XI}"', "", 1)  # declared by the root
    return "  " * level + text + "\n"


def _mesh_name(grid: ElementTree.Element) -> str:
    """The name of the mesh an output time's grid refers to."""
    return re.search(r"@Name='([^']+)'", grid.find(f"{{{XI}}}include").get("xpointer")).group(1)


def _time(grid: ElementTree.Element) -> int:
    """The output time (its k) whose file an output time's grid refers to."""
    return int(pathlib.Path(grid.find(".//DataItem").text.strip().split(":", 1)[0]).stem)


class Index:
    """``solution.xdmf`` (``path``) in memory, as the XML of its grids, and its folder
    ``path.parent / FOLDER`` (rank 0). ``fresh`` starts an empty pair, ``resume`` keeps a run's
    first output times."""

    def __init__(self, path: pathlib.Path):
        self.path = pathlib.Path(path)
        self.folder = self.path.parent / FOLDER
        self.meshes: dict[str, str] = {}  # name -> XML of its grid
        # field -> (attributes of its temporal collection, [(k, mesh name, XML of the grid)])
        self.fields: dict[str, tuple[dict, list[tuple[int, str, str]]]] = {}
        self.mesh: ElementTree.Element | None = None  # the grid of the mesh new output times refer to
        self.unsynced: list[pathlib.Path] = []  # files put in place since the last sync

    @classmethod
    def fresh(cls, path: pathlib.Path) -> Index:
        """An empty index; any earlier ``path``, its HDF5 file and folder are removed."""
        path = pathlib.Path(path)
        path.unlink(missing_ok=True)
        path.with_suffix(".h5").unlink(missing_ok=True)
        shutil.rmtree(path.parent / FOLDER, ignore_errors=True)
        (path.parent / FOLDER).mkdir()
        return cls(path)

    @classmethod
    def resume(cls, path: pathlib.Path, writes: int) -> Index:
        """The index of ``path`` cut to its first ``writes`` output times, published, and the
        files it no longer lists removed (the later times and meshes, a killed writer's files)."""
        index = cls(path)
        try:
            domain = ElementTree.parse(index.path).getroot().find("Domain")
        except (OSError, ElementTree.ParseError) as err:
            raise OutputError(f"cannot read {path} to resume its run: {err}") from err
        meshes = {grid.get("Name"): _text(grid, 2) for grid in domain.findall("Grid[@GridType='Uniform']")}
        for collection in domain.findall("Grid[@GridType='Collection']"):
            grids = [(_time(g), _mesh_name(g), _text(g, 3)) for g in collection.findall("Grid")]
            index.fields[collection.get("Name")] = (dict(collection.attrib), [g for g in grids if g[0] < writes])
        listed = {k for _, grids in index.fields.values() for k, _, _ in grids}
        if listed != set(range(writes)) or not meshes:
            raise OutputError(f"{path} lists {len(listed)} of the {writes} output times of the checkpoint: the "
                              "solution files do not belong to it")
        used = {next(iter(meshes))} | {mesh for _, grids in index.fields.values() for _, mesh, _ in grids}
        index.meshes = {name: text for name, text in meshes.items() if name in used}
        index.publish()
        listed = set(re.findall(rf">\s*{FOLDER}/([^<>:/]+):", "".join(index.meshes.values()) + "".join(
            text for _, grids in index.fields.values() for _, _, text in grids)))
        for stale in index.folder.iterdir():
            if stale.name not in listed:
                stale.unlink()
        return index

    def next_mesh(self) -> str:
        """The name of the mesh of a new part: "mesh" first, then the first unused ``mesh_<k>``."""
        return next(name for name in ("mesh", *(f"mesh_{k}" for k in range(1, len(self.meshes) + 1)))
                    if name not in self.meshes)

    def add_mesh(self, name: str) -> None:
        """List the mesh DOLFINx wrote to the hidden pair of ``name`` (its grid renamed ``name``)
        as the one new output times refer to, and publish."""
        xml = hidden(self.folder, name, ".xdmf")
        mesh = _dolfinx_xml(xml).find("Domain/Grid")
        mesh.set("Name", name)
        self._move([mesh], f"{name}.h5", self.path.with_suffix(".h5") if name == "mesh" else None)
        self.mesh, self.meshes[name] = mesh, _text(mesh, 2)
        xml.unlink()
        self.publish()

    def time_template(self, k: int) -> None:
        """Write the XML from which DOLFINx writes the k-th output time: the mesh alone, and the
        XInclude prefix that DOLFINx uses without declaring it (a hidden file left by a killed
        writer is removed first)."""
        hidden(self.folder, time_file(k), ".h5").unlink(missing_ok=True)
        text = f'<Xdmf Version="3.0" xmlns:xi="{XI}">\n  <Domain>\n{_text(self.mesh, 2)}  </Domain>\n</Xdmf>\n'
        hidden(self.folder, time_file(k), ".xdmf").write_text(_HEADER + text)

    def add_time(self, k: int) -> None:
        """List the k-th output time that DOLFINx wrote from its template, and publish."""
        xml = hidden(self.folder, time_file(k), ".xdmf")
        collections = _dolfinx_xml(xml).findall("Domain/Grid[@GridType='Collection']")
        grids = [(collection, grid) for collection in collections for grid in collection.findall("Grid")]
        self._move([grid for _, grid in grids], time_file(k))
        for collection, grid in grids:
            entry = self.fields.setdefault(collection.get("Name"), (dict(collection.attrib), []))
            entry[1].append((k, self.mesh.get("Name"), _text(grid, 3)))
        xml.unlink()
        self.publish()

    def _move(self, elements: list[ElementTree.Element], name: str, target: pathlib.Path | None = None) -> None:
        """Put DOLFINx's hidden HDF5 file of ``name`` in place, as ``target`` (default: ``name``
        in the folder), and point the data items of ``elements`` to it."""
        target = target or self.folder / name
        os.replace(hidden(self.folder, name, ".h5"), target)
        self.unsynced.append(target)
        reference = target.relative_to(self.path.parent).as_posix()
        for item in (item for element in elements for item in element.iter("DataItem")):
            item.text = f"{reference}:{item.text.strip().split(':', 1)[1]}"

    def publish(self) -> None:
        """Replace ``solution.xdmf`` atomically by the index."""
        parts = [_HEADER, f'<Xdmf Version="3.0" xmlns:xi="{XI}">\n  <Domain>\n', *self.meshes.values()]
        for attributes, grids in self.fields.values():
            if grids:
                opening = " ".join(f"{key}={quoteattr(value)}" for key, value in attributes.items())
                parts += [f"    <Grid {opening}>\n", *(text for _, _, text in grids), "    </Grid>\n"]
        tmp = self.path.with_suffix(".xdmf.tmp")
        tmp.write_text("".join(parts) + "  </Domain>\n</Xdmf>\n")
        os.replace(tmp, self.path)

    def sync(self) -> None:
        """Put the files listed so far on disk (fsync): the HDF5 files put in place since the last
        sync, the folder, ``solution.xdmf`` and the output folder."""
        for path in [*self.unsynced, self.folder, self.path, self.path.parent]:
            fsync(path)
        self.unsynced = []
