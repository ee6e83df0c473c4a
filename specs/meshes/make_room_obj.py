"""Writes specs/meshes/room.obj, the mesh of the README's Python example (run from the repo root).

A 5 x 4 x 2.7 m room (normals into the air) with a 2 x 0.9 x 0.8 m sofa, one obj object per
label: floor, walls, ceiling, sofa. `Scene.from_file` labels faces by these object names.
"""

from pathlib import Path

from sonicspec.geometry.procedural import add_obstacles, box_obstacle, shoebox

room = add_obstacles(shoebox([5.0, 4.0, 2.7]),
                     [box_obstacle([2.5, 0.6, 0.4], [2.0, 0.9, 0.8], label="sofa")])
names = {"wall": "walls", "floor": "floor", "ceiling": "ceiling", "sofa": "sofa"}
lines = ["# specs/meshes/room.obj: written by specs/meshes/make_room_obj.py"]
lines += [f"v {x:g} {y:g} {z:g}" for x, y, z in room.vertices]
for index, label in enumerate(room.labels):
    lines.append(f"o {names[label]}")
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in room.faces[room.face_label == index]]
Path(__file__).with_name("room.obj").write_text("\n".join(lines) + "\n")
