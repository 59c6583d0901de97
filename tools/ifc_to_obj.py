#!/usr/bin/env python3
"""The coarse OBJ building model of an IFC file, through IfcOpenShell.

    python3 tools/ifc_to_obj.py FILE.ifc --out MODEL.obj [--storey NAME]

`omnitrack-desk model from-ifc` runs this (the binary carries a copy and writes it into the
cache directory); it is not meant to be called by hand, but it can be. The script creates (or
reuses) a venv in the per-user cache, never in the source tree: `$OMNITRACK_IFC_VENV` if set (the
binary sets it), else `ifc-venv` in `$OMNITRACK_CACHE`, `$XDG_CACHE_HOME/omnitrack` or
`~/.cache/omnitrack`; installs IfcOpenShell (PyPI `ifcopenshell`) into it once, saying so on
stderr, under a lock so that two conversions never install at once; and re-runs itself there.

Kept: the building's coarse elements, the ones a camera sees as long straight lines that stay
where the architect drew them: walls, slabs (floors, roofs' slabs, landings), roofs, doors,
windows, stairs and their flights, columns, beams, curtain walls and the plates and members they
are made of. Left out: furniture, services (ducts, pipes, cables, terminals), railings, spaces,
annotations, openings (already cut out of the walls by IfcOpenShell) and anything else.

Out: Wavefront OBJ in metres, z up, world = the IFC project's coordinates (every placement
applied); one `o` record per element named `<IfcClass>_<GlobalId>`, its faces the triangles
IfcOpenShell tessellates (the tracker's loader merges coplanar triangles, so diagonals are not
model segments). Stderr: one line per storey (elements kept by class, triangles) and one for
elements whose geometry IfcOpenShell could not make (skipped and counted).

Errors are one line on stderr and exit code 2: a file that is not IFC, an unknown storey (the
line lists the storeys there are), a model (or storey) with no walls.
"""
import os
import subprocess
import sys


def cache_venv():
    """Where IfcOpenShell lives: the per-user cache's `ifc-venv` (see the module's doc)."""
    explicit = os.environ.get("OMNITRACK_IFC_VENV")
    if explicit:
        return explicit
    cache = os.environ.get("OMNITRACK_CACHE")
    if not cache:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = xdg if xdg and os.path.isabs(xdg) else os.path.join(os.path.expanduser("~"), ".cache")
        cache = os.path.join(base, "omnitrack")
    return os.path.join(cache, "ifc-venv")


VENV = cache_venv()
PY = os.path.join(VENV, "bin", "python")

# Coarse classes (IfcOpenShell's by_type includes subtypes: IfcWall gives IfcWallStandardCase).
KEPT = [
    "IfcWall",
    "IfcSlab",
    "IfcRoof",
    "IfcDoor",
    "IfcWindow",
    "IfcStair",
    "IfcStairFlight",
    "IfcColumn",
    "IfcBeam",
    "IfcCurtainWall",
]
# Kept only as parts of a kept element (a curtain wall's panels and mullions).
PARTS = ["IfcPlate", "IfcMember"]


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(2)


def ensure_venv():
    if os.path.abspath(sys.prefix) == os.path.abspath(VENV):
        return
    try:
        os.makedirs(os.path.dirname(VENV) or ".", exist_ok=True)
        # One installer at a time: a second conversion waits here, then finds IfcOpenShell there.
        with open(VENV + ".lock", "w") as lock:
            try:
                import fcntl

                fcntl.flock(lock, fcntl.LOCK_EX)
            except ImportError:  # not POSIX: no lock, as before
                pass
            if not os.path.exists(PY):
                print(f"from-ifc: creating the venv {VENV} (once)", file=sys.stderr, flush=True)
                subprocess.check_call([sys.executable, "-m", "venv", VENV], stdout=subprocess.DEVNULL)
            probe = subprocess.run([PY, "-c", "import ifcopenshell.geom"], capture_output=True)
            if probe.returncode != 0:
                print(
                    f"from-ifc: installing IfcOpenShell (PyPI ifcopenshell) into {VENV}, once: about 20 s",
                    file=sys.stderr,
                    flush=True,
                )
                subprocess.check_call(
                    [PY, "-m", "pip", "install", "-q", "--disable-pip-version-check", "ifcopenshell"],
                    stdout=subprocess.DEVNULL,
                )
    except (OSError, subprocess.CalledProcessError) as e:
        fail(f"cannot set up IfcOpenShell in {VENV}: {e}")
    os.execv(PY, [PY] + sys.argv)


def check_input(path):
    """A missing file or one that is not IFC is said before any venv is made or installed."""
    if not os.path.isfile(path):
        fail(f"{path}: no such file")
    with open(path, "rb") as fh:
        head = fh.read(64)
    if not head.lstrip().startswith(b"ISO-10303-21"):
        fail(f"{path}: not an IFC file (an IFC file starts with ISO-10303-21; IFC-XML and ifcZIP are not read)")


def parse_args(argv):
    path, out, storey = None, None, None
    it = iter(argv)
    for a in it:
        if a == "--out":
            out = next(it, None)
        elif a == "--storey":
            storey = next(it, None)
            if storey is None:
                fail("--storey needs a name")
        elif path is None and not a.startswith("--"):
            path = a
        else:
            fail(f"unexpected argument {a!r} (usage: ifc_to_obj.py FILE.ifc --out MODEL.obj [--storey NAME])")
    if path is None or out is None:
        fail("usage: ifc_to_obj.py FILE.ifc --out MODEL.obj [--storey NAME]")
    return path, out, storey


def storey_of(element, util):
    """The IfcBuildingStorey that holds `element` (through its container, or the element it is
    part of, or the space it stands in), or None."""
    seen = set()
    e = element
    while e is not None and e.id() not in seen:
        seen.add(e.id())
        if e.is_a("IfcBuildingStorey"):
            return e
        parent = util.get_container(e) if not e.is_a("IfcSpatialElement") else None
        if parent is None:
            parent = util.get_aggregate(e)
        e = parent
    return None


def main():
    path, out, storey_name = parse_args(sys.argv[1:])
    check_input(path)
    ensure_venv()
    import ifcopenshell
    import ifcopenshell.geom
    import ifcopenshell.util.element as util
    import ifcopenshell.util.unit as unit

    try:
        model = ifcopenshell.open(path)
    except Exception as e:  # IfcOpenShell raises its own types for every parse failure
        fail(f"{path}: not a readable IFC file: {str(e).splitlines()[0] if str(e) else type(e).__name__}")

    storeys = model.by_type("IfcBuildingStorey")
    if storey_name is not None and not any(s.Name == storey_name for s in storeys):
        names = ", ".join(repr(s.Name) for s in storeys) or "none"
        fail(f"{path}: no storey named {storey_name!r} (storeys: {names})")

    chosen = {}
    for cls in KEPT:
        for e in model.by_type(cls):
            chosen[e.id()] = e
    for cls in PARTS:
        for e in model.by_type(cls):
            whole = util.get_aggregate(e)
            if whole is not None and whole.id() in chosen:
                chosen[e.id()] = e
    elements = [e for e in chosen.values() if e.Representation is not None]
    if storey_name is not None:
        elements = [e for e in elements if (s := storey_of(e, util)) is not None and s.Name == storey_name]
    where = f" on storey {storey_name!r}" if storey_name is not None else ""
    if not any(e.is_a("IfcWall") for e in elements):
        fail(f"{path}: no walls (IfcWall with a shape){where}: nothing to build a building model from")

    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    scale = unit.calculate_unit_scale(model)

    by_storey = {}
    lines = [f"# omnitrack-desk model from-ifc {os.path.basename(path)}{where}; metres, z up\n"]
    base = 1
    failed = 0
    triangles_total = 0
    iterator = ifcopenshell.geom.iterator(settings, model, max(1, os.cpu_count() or 1), include=elements)
    done = set()
    if iterator.initialize():
        while True:
            shape = iterator.get()
            element = model.by_id(shape.id)
            done.add(shape.id)
            verts = shape.geometry.verts
            faces = shape.geometry.faces
            n = len(verts) // 3
            if n >= 3 and len(faces) >= 3 and all(map(_finite, verts)):
                lines.append(f"o {element.is_a()}_{element.GlobalId}\n")
                for k in range(n):
                    x, y, z = verts[3 * k : 3 * k + 3]
                    lines.append(f"v {x:.6f} {y:.6f} {z:.6f}\n")
                for k in range(0, len(faces) - 2, 3):
                    a, b, c = faces[k : k + 3]
                    lines.append(f"f {a + base} {b + base} {c + base}\n")
                base += n
                triangles = len(faces) // 3
                triangles_total += triangles
                s = storey_of(element, util)
                key = s.id() if s is not None else None
                entry = by_storey.setdefault(key, [s, {}, 0])
                cls = _coarse_class(element)
                entry[1][cls] = entry[1].get(cls, 0) + 1
                entry[2] += triangles
            else:
                failed += 1
            if not iterator.next():
                break
    failed += sum(1 for e in elements if e.id() not in done)
    if triangles_total == 0:
        fail(f"{path}: IfcOpenShell made no geometry for the {len(elements)} elements kept{where}")

    with open(out, "w") as fh:
        fh.writelines(lines)

    def order(item):
        s = item[1][0]
        return (s is None, _elevation(s, scale) if s is not None else 0.0)

    for _, (s, counts, triangles) in sorted(by_storey.items(), key=order):
        name = f"storey {s.Name!r} (elevation {_elevation(s, scale):.2f} m)" if s is not None else "no storey"
        kinds = ", ".join(f"{n} {cls}" for cls, n in sorted(counts.items()))
        print(f"{os.path.basename(path)}: {name}: {kinds}; {triangles} triangles", file=sys.stderr)
    if failed:
        print(f"{os.path.basename(path)}: {failed} elements without usable geometry skipped", file=sys.stderr)


def _finite(v):
    return v == v and abs(v) < 1e7


def _elevation(storey, scale):
    return (storey.Elevation or 0.0) * scale


def _coarse_class(element):
    for cls in KEPT + PARTS:
        if element.is_a(cls):
            return {
                "IfcWall": "walls",
                "IfcSlab": "slabs",
                "IfcRoof": "roofs",
                "IfcDoor": "doors",
                "IfcWindow": "windows",
                "IfcStair": "stairs",
                "IfcStairFlight": "stair flights",
                "IfcColumn": "columns",
                "IfcBeam": "beams",
                "IfcCurtainWall": "curtain walls",
                "IfcPlate": "curtain-wall plates",
                "IfcMember": "curtain-wall members",
            }[cls]
    return element.is_a()


if __name__ == "__main__":
    main()
