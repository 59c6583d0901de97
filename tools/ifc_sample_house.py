#!/usr/bin/env python3
"""A small IFC4 house written with IfcOpenShell's authoring API, for the tests of
`omnitrack-desk model from-ifc` (public IFC samples may not be committed, and this one is ours).

    python3 tools/ifc_sample_house.py OUT.ifc

Two storeys ("Ground", elevation 0, and "Upper", elevation 3 m), lengths in millimetres as
architects' files usually are. Ground: four walls round a 6 × 4 m room (200 mm thick, 2.8 m
high), one with a door opening 0.9 × 2.1 m, a floor slab, a door, a column; plus what the
converter must leave out: a table (IfcFurniture), a duct segment and a railing. Upper: four
walls and a slab. Runs in the venv of ifc_to_obj.py (in the per-user cache).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ifc_to_obj  # noqa: E402  (its venv)


def main():
    if len(sys.argv) != 2:
        ifc_to_obj.fail("usage: ifc_sample_house.py OUT.ifc")
    ifc_to_obj.ensure_venv()
    import numpy as np
    import ifcopenshell
    import ifcopenshell.api as api

    f = ifcopenshell.file(schema="IFC4")
    project = api.run("root.create_entity", f, ifc_class="IfcProject", name="Sample house")
    api.run("unit.assign_unit", f, units=[api.run("unit.add_si_unit", f, unit_type="LENGTHUNIT", prefix="MILLI")])
    model3d = api.run("context.add_context", f, context_type="Model")
    body = api.run(
        "context.add_context", f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW",
        parent=model3d,
    )
    site = api.run("root.create_entity", f, ifc_class="IfcSite", name="Site")
    building = api.run("root.create_entity", f, ifc_class="IfcBuilding", name="House")
    api.run("aggregate.assign_object", f, products=[site], relating_object=project)
    api.run("aggregate.assign_object", f, products=[building], relating_object=site)

    def place(product, x, y, z, yaw_deg=0.0):
        c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
        m = np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1]], dtype=float)
        api.run("geometry.edit_object_placement", f, product=product, matrix=m, is_si=True)

    def element(cls, storey, name):
        e = api.run("root.create_entity", f, ifc_class=cls, name=name)
        api.run("spatial.assign_container", f, products=[e], relating_structure=storey)
        return e

    def walls_round(storey, z, prefix):
        # A 6 × 4 m room: walls 200 mm thick along the outside of the rectangle.
        made = []
        for k, (x, y, yaw, length) in enumerate(
            [(0, 0, 0, 6.0), (6.0, 0, 90, 4.0), (6.0, 4.0, 180, 6.0), (0, 4.0, 270, 4.0)]
        ):
            w = element("IfcWall", storey, f"{prefix} wall {k}")
            rep = api.run(
                "geometry.add_wall_representation", f, context=body, length=length, height=2.8, thickness=0.2
            )
            api.run("geometry.assign_representation", f, product=w, representation=rep)
            place(w, x, y, z, yaw)
            made.append(w)
        return made

    def slab(storey, z, name):
        s = element("IfcSlab", storey, name)
        rep = api.run(
            "geometry.add_slab_representation",
            f,
            context=body,
            depth=0.2,
            polyline=[(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)],
        )
        api.run("geometry.assign_representation", f, product=s, representation=rep)
        place(s, 0, 0, z - 0.2)
        return s

    ground = api.run("root.create_entity", f, ifc_class="IfcBuildingStorey", name="Ground")
    upper = api.run("root.create_entity", f, ifc_class="IfcBuildingStorey", name="Upper")
    ground.Elevation = 0.0
    upper.Elevation = 3000.0  # project units (mm)
    api.run("aggregate.assign_object", f, products=[ground, upper], relating_object=building)

    walls = walls_round(ground, 0, "ground")
    slab(ground, 0, "ground floor")
    # A door opening in the first wall, 2 m along it, and the door standing in it.
    opening = api.run("root.create_entity", f, ifc_class="IfcOpeningElement", name="door opening")
    rep = api.run("geometry.add_wall_representation", f, context=body, length=0.9, height=2.1, thickness=0.4)
    api.run("geometry.assign_representation", f, product=opening, representation=rep)
    place(opening, 2.0, -0.1, 0)
    api.run("feature.add_feature", f, feature=opening, element=walls[0])
    door = element("IfcDoor", ground, "door")
    rep = api.run("geometry.add_wall_representation", f, context=body, length=0.9, height=2.1, thickness=0.05)
    api.run("geometry.assign_representation", f, product=door, representation=rep)
    place(door, 2.0, 0.075, 0)
    column = element("IfcColumn", ground, "column")
    rep = api.run("geometry.add_profile_representation", f, context=body,
                  profile=f.createIfcRectangleProfileDef("AREA", None, None, 300.0, 300.0), depth=2.8)
    api.run("geometry.assign_representation", f, product=column, representation=rep)
    place(column, 4.5, 2.0, 0)
    # Left out by the converter.
    for cls, name, at in [("IfcFurniture", "table", (3.0, 2.0, 0)), ("IfcDuctSegment", "duct", (1.0, 3.0, 2.5)),
                          ("IfcRailing", "railing", (5.0, 1.0, 0))]:
        e = element(cls, ground, name)
        rep = api.run("geometry.add_wall_representation", f, context=body, length=0.8, height=0.75, thickness=0.6)
        api.run("geometry.assign_representation", f, product=e, representation=rep)
        place(e, *at)

    walls_round(upper, 3.0, "upper")
    slab(upper, 3.0, "upper floor")
    f.write(sys.argv[1])


if __name__ == "__main__":
    main()
