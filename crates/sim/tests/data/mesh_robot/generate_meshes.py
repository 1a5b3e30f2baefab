#!/usr/bin/env python3
"""Writes the meshes of the test package mesh_robot_description (run once; output is committed).

    python3 crates/sim/tests/data/mesh_robot/generate_meshes.py

Every mesh is a closed prism (a polygon swept along an axis) with outward-facing triangles:

- base.stl    binary STL, cylinder r = 0.08 m, z in [0, 0.1], 24 sides      -> 92 triangles
- link1.stl   ASCII STL, box 60 x 60 x 300 in MILLIMETRES (the URDF scales it
              by 0.001), x, y in [-30, 30], z in [0, 300]                     -> 12 triangles
- link2.obj   OBJ with quad sides and 16-gon caps (the loader triangulates),
              cylinder r = 0.03 m, z in [0, 0.25], 16 sides                  -> 60 triangles
- gripper.dae COLLADA, a U-shaped (concave) jaw: x in [-0.05, 0.05],
              y in [-0.02, 0.02], z in [0, 0.08]                             -> 28 triangles

The Rust tests (crates/sim/tests/mesh_urdf.rs) check these counts and bounds.
"""

import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
MESHES = os.path.join(HERE, "mesh_robot_description", "meshes")


def prism(polygon, c0, c1, cap_triangles=None):
    """A polygon (counter-clockwise in the (a, b) plane) swept along c from c0 to c1.

    Returns (vertices as (a, b, c), faces as lists of vertex indices, outward winding).
    Caps are one polygon each unless `cap_triangles` (index triples into `polygon`, also
    counter-clockwise) triangulates a concave outline. Sides are quads.
    """
    n = len(polygon)
    vertices = [(a, b, c0) for a, b in polygon] + [(a, b, c1) for a, b in polygon]
    caps = cap_triangles or [list(range(n))]
    faces = [list(reversed(f)) for f in caps]  # bottom cap faces -c
    faces += [[i + n for i in f] for f in caps]  # top cap faces +c
    for i in range(n):
        j = (i + 1) % n
        faces.append([i, j, j + n, i + n])
    return vertices, faces


def regular_polygon(radius, sides):
    return [
        (radius * math.cos(2 * math.pi * k / sides), radius * math.sin(2 * math.pi * k / sides))
        for k in range(sides)
    ]


def triangulate(faces):
    """Fan triangulation; valid for the convex faces `prism` makes."""
    return [(f[0], f[k], f[k + 1]) for f in faces for k in range(1, len(f) - 1)]


def sub(u, v):
    return tuple(x - y for x, y in zip(u, v))


def cross(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def unit_normal(p0, p1, p2):
    n = cross(sub(p1, p0), sub(p2, p0))
    length = math.sqrt(sum(x * x for x in n)) or 1.0
    return tuple(x / length for x in n)


def check_closed_and_outward(vertices, triangles, polygon, height):
    """The signed volume of outward triangles equals the prism volume (shoelace area x height)."""
    volume = sum(
        sum(a * b for a, b in zip(vertices[i], cross(vertices[j], vertices[k])))
        for i, j, k in triangles
    ) / 6.0
    area = 0.5 * sum(
        polygon[i][0] * polygon[(i + 1) % len(polygon)][1]
        - polygon[(i + 1) % len(polygon)][0] * polygon[i][1]
        for i in range(len(polygon))
    )
    assert abs(volume - area * height) < 1e-9 * max(1.0, abs(area * height)), (volume, area)


def num(x):
    text = "%.9g" % x
    return "0" if text == "-0" else text


def write_binary_stl(path, vertices, triangles):
    out = bytearray(b"fairgrasp test mesh base.stl (binary)".ljust(80, b" "))
    out += struct.pack("<I", len(triangles))
    for tri in triangles:
        p = [vertices[i] for i in tri]
        out += struct.pack("<3f", *unit_normal(*p))
        for v in p:
            out += struct.pack("<3f", *v)
        out += struct.pack("<H", 0)
    with open(path, "wb") as f:
        f.write(out)


def write_ascii_stl(path, name, vertices, triangles):
    lines = [f"solid {name}"]
    for tri in triangles:
        p = [vertices[i] for i in tri]
        lines.append("  facet normal " + " ".join(num(x) for x in unit_normal(*p)))
        lines.append("    outer loop")
        lines += ["      vertex " + " ".join(num(x) for x in v) for v in p]
        lines.append("    endloop")
        lines.append("  endfacet")
    lines.append(f"endsolid {name}")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_obj(path, vertices, faces):
    lines = ["# fairgrasp test mesh link2.obj: cylinder, quad sides, 16-gon caps", "o link2"]
    lines += ["v " + " ".join(num(x) for x in v) for v in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_dae(path, vertices, triangles):
    positions = " ".join(num(x) for v in vertices for x in v)
    indices = " ".join(str(i) for tri in triangles for i in tri)
    text = f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset>
    <contributor><authoring_tool>fairgrasp generate_meshes.py</authoring_tool></contributor>
    <unit name="meter" meter="1"/>
    <up_axis>Z_UP</up_axis>
  </asset>
  <library_geometries>
    <geometry id="jaw-mesh" name="jaw">
      <mesh>
        <source id="jaw-positions">
          <float_array id="jaw-positions-array" count="{3 * len(vertices)}">{positions}</float_array>
          <technique_common>
            <accessor source="#jaw-positions-array" count="{len(vertices)}" stride="3">
              <param name="X" type="float"/>
              <param name="Y" type="float"/>
              <param name="Z" type="float"/>
            </accessor>
          </technique_common>
        </source>
        <vertices id="jaw-vertices">
          <input semantic="POSITION" source="#jaw-positions"/>
        </vertices>
        <triangles count="{len(triangles)}">
          <input semantic="VERTEX" source="#jaw-vertices" offset="0"/>
          <p>{indices}</p>
        </triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="Scene" name="Scene">
      <node id="jaw" name="jaw" type="NODE">
        <instance_geometry url="#jaw-mesh" name="jaw"/>
      </node>
    </visual_scene>
  </library_visual_scenes>
  <scene>
    <instance_visual_scene url="#Scene"/>
  </scene>
</COLLADA>
"""
    with open(path, "w") as f:
        f.write(text)


def main():
    os.makedirs(MESHES, exist_ok=True)

    # base.stl: binary STL cylinder.
    polygon = regular_polygon(0.08, 24)
    vertices, faces = prism(polygon, 0.0, 0.1)
    triangles = triangulate(faces)
    check_closed_and_outward(vertices, triangles, polygon, 0.1)
    assert len(triangles) == 92
    write_binary_stl(os.path.join(MESHES, "base.stl"), vertices, triangles)

    # link1.stl: ASCII STL box in millimetres.
    polygon = [(-30.0, -30.0), (30.0, -30.0), (30.0, 30.0), (-30.0, 30.0)]
    vertices, faces = prism(polygon, 0.0, 300.0)
    triangles = triangulate(faces)
    check_closed_and_outward(vertices, triangles, polygon, 300.0)
    assert len(triangles) == 12
    write_ascii_stl(os.path.join(MESHES, "link1.stl"), "link1", vertices, triangles)

    # link2.obj: cylinder kept as polygons; the loader fan-triangulates them.
    polygon = regular_polygon(0.03, 16)
    vertices, faces = prism(polygon, 0.0, 0.25)
    triangles = triangulate(faces)
    check_closed_and_outward(vertices, triangles, polygon, 0.25)
    assert len(triangles) == 60
    write_obj(os.path.join(MESHES, "link2.obj"), vertices, faces)

    # gripper.dae: a U-shaped jaw (palm and two fingers), outline in the (x, z) plane.
    w, h, t, b, d = 0.05, 0.08, 0.015, 0.02, 0.04
    outline = [(-w, 0), (w, 0), (w, h), (w - t, h), (w - t, b), (-w + t, b), (-w + t, h), (-w, h)]
    cap = [[0, 1, 4], [0, 4, 5], [1, 2, 3], [1, 3, 4], [0, 5, 6], [0, 6, 7]]
    vertices, faces = prism(outline, -d / 2, d / 2, cap)
    triangles = triangulate(faces)
    check_closed_and_outward(vertices, triangles, outline, d)
    # (a, b, c) -> (x, y, z) = (a, -c, b) is a proper rotation, so the winding stays outward.
    vertices = [(a, -c, bb) for a, bb, c in vertices]
    assert len(triangles) == 28
    write_dae(os.path.join(MESHES, "gripper.dae"), vertices, triangles)


if __name__ == "__main__":
    main()
