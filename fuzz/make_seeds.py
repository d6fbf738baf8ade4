#!/usr/bin/env python3
"""Writes the committed seed corpora under fuzz/seeds/<target>/ (small, valid inputs).

Run from anywhere: `python3 fuzz/make_seeds.py`. Inputs come from the bundled data
(data/psb/*.off, data/demo/*.json) or are written here; `requests` seeds are protobuf encodings
of the service's request messages, prefixed with the selector byte the target reads.
"""
import json
import pathlib
import struct

FUZZ = pathlib.Path(__file__).resolve().parent
ROOT = FUZZ.parent
SEEDS = FUZZ / "seeds"


def put(target, name, data):
    d = SEEDS / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data if isinstance(data, bytes) else data.encode())


def off_prefix(path, nv, nf):
    """The first nv vertices of a PSB OFF file and its first nf faces among them."""
    lines = [l for l in path.read_text().splitlines() if l.strip()]
    v_all, f_all = map(int, lines[1].split()[:2])
    verts = lines[2 : 2 + nv]
    faces = [l for l in lines[2 + v_all : 2 + v_all + f_all] if all(int(i) < nv for i in l.split()[1:])][:nf]
    return "OFF\n%d %d 0\n%s\n%s\n" % (nv, len(faces), "\n".join(verts), "\n".join(faces))


# --- meshes -----------------------------------------------------------------------------------
TETRA = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.5, 0.0), (0.0, 0.0, -0.2)]
TRIS = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]

put("mesh_off", "chair_101_head.off", off_prefix(ROOT / "data/psb/chair_101.off", 24, 16))
put("mesh_off", "octopus_121_head.off", off_prefix(ROOT / "data/psb/octopus_121.off", 12, 8))
put("mesh_off", "tetra_comments.off", "OFF\n# a comment\n4 4 0\n0 0 0\n1 0 0\n0 1.5 0\n0 0 -2e-1\n3 0 1 2\n3 0 1 3\n3 0 2 3\n3 1 2 3\n")
put("mesh_off", "counts_on_header.off", "OFF 1 0 0\n1 2 3\n")

put("mesh_xyz", "tetra.xyz", "".join("%g %g %g\n" % v for v in TETRA))
put("mesh_xyz", "commas_normals.xyz", "# x,y,z,nx,ny,nz\n1,2,3,0,0,1\n\n4, 5, 6 0 1 0\n-1e-3 2.5E2 7\n")

put("mesh_obj", "tetra.obj", "# tetra\no tetra\n" + "".join("v %g %g %g\n" % v for v in TETRA) + "".join("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in TRIS))
put(
    "mesh_obj",
    "quad_uv_normals.obj",
    "mtllib none.mtl\ng quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 1\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n"
    "usemtl none\nf 1/1/1 2/2/1 3/3/1 4//1\nf -4 -3 -2\nl 1 2\n",
)

facets = "".join(
    "facet normal 0 0 1\n outer loop\n" + "".join("  vertex %g %g %g\n" % TETRA[i] for i in t) + " endloop\nendfacet\n" for t in TRIS
)
put("mesh_stl", "tetra_ascii.stl", "solid tetra\n" + facets + "endsolid tetra\n")


def stl_binary(header):
    out = header.ljust(80, b"\0")[:80] + struct.pack("<I", len(TRIS))
    for t in TRIS:
        out += struct.pack("<3f", 0, 0, 1) + b"".join(struct.pack("<3f", *TETRA[i]) for i in t) + b"\0\0"
    return out


put("mesh_stl", "tetra_binary.stl", stl_binary(b"binary tetra"))
put("mesh_stl", "tetra_binary_solid_header.stl", stl_binary(b"solid but binary"))


def ply(fmt, body_header, payload):
    return ("ply\nformat %s 1.0\ncomment seed\n%send_header\n" % (fmt, body_header)).encode() + payload


PLY_HEAD = "element vertex 4\nproperty float x\nproperty float y\nproperty double z\nproperty uchar red\nelement face 4\nproperty list uchar int vertex_indices\n"
ascii_body = "".join("%g %g %g 200\n" % v for v in TETRA) + "".join("3 %d %d %d\n" % t for t in TRIS)
put("mesh_ply", "tetra_ascii.ply", ply("ascii", PLY_HEAD, ascii_body.encode()))
for fmt, e in (("binary_little_endian", "<"), ("binary_big_endian", ">")):
    payload = b"".join(struct.pack(e + "ffdB", *v, 200) for v in TETRA)
    payload += b"".join(struct.pack(e + "Biii", 3, *t) for t in TRIS)
    put("mesh_ply", "tetra_%s.ply" % fmt, ply(fmt, PLY_HEAD, payload))
put("mesh_ply", "crlf_short_types.ply", b"ply\r\nformat ascii 1.0\r\nelement vertex 2\r\nproperty short x\r\nproperty int y\r\nproperty char z\r\nend_header\r\n1 2 3\r\n-4 5 -6\r\n")

# --- bodies -----------------------------------------------------------------------------------
for name in ("chair_101", "human_10"):
    text = (ROOT / "data/demo" / (name + ".json")).read_text()
    put("body_json", name + ".json", json.dumps(json.loads(text), separators=(",", ":")))
put("body_json", "sphere_deg2.json", '{"degree":2,"exponents":[[0,0,0],[2,0,0],[0,2,0],[0,0,2]],"coefficients":[0,1,1,1],"center":[0,0,0],"scale":1}')


# --- requests (protobuf by hand) ----------------------------------------------------------------
def varint(n):
    out = b""
    while True:
        b, n = n & 0x7F, n >> 7
        out += bytes([b | (0x80 if n else 0)])
        if not n:
            return out


def f_varint(no, n):
    return varint(no << 3) + varint(n)


def f_double(no, x):
    return varint(no << 3 | 1) + struct.pack("<d", x)


def f_bytes(no, b):
    b = b if isinstance(b, bytes) else b.encode()
    return varint(no << 3 | 2) + varint(len(b)) + b


def packed_doubles(no, xs):
    return f_bytes(no, b"".join(struct.pack("<d", x) for x in xs))


def vec3(x, y, z):
    return f_double(1, x) + f_double(2, y) + f_double(3, z)


def pose(q, t):
    quat = f_double(1, q[0]) + f_double(2, q[1]) + f_double(3, q[2]) + f_double(4, q[3])
    return f_bytes(1, quat) + f_bytes(2, vec3(*t))


cube = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
fit_points = f_bytes(1, "cube") + f_varint(2, 4) + f_bytes(3, packed_doubles(1, [c for p in cube for c in p])) + f_bytes(5, "trace_p") + f_double(6, 0.5)
put("requests", "start_fit_points.bin", b"\x00" + fit_points)
mesh = (SEEDS / "mesh_off" / "tetra_comments.off").read_bytes()
put("requests", "start_fit_mesh_auto.bin", b"\x00" + f_bytes(1, "tetra") + f_bytes(4, f_bytes(1, mesh) + f_bytes(2, "off")) + f_varint(7, 1) + f_double(8, 0.1))

demo = json.loads((ROOT / "data/demo/chair_101.json").read_text())
put("requests", "upload_json.bin", b"\x01" + f_bytes(1, "chair") + f_bytes(2, (SEEDS / "body_json" / "sphere_deg2.json").read_text()))
body_data = (
    f_varint(1, demo["degree"])
    + f_bytes(2, b"".join(varint(e) for t in demo["exponents"] for e in t))
    + packed_doubles(3, demo["coefficients"])
    + f_bytes(4, vec3(*demo["center"]))
    + f_double(5, demo["scale"])
    + f_bytes(6, f_bytes(1, "uploaded") + f_double(11, 1.0))
)
put("requests", "upload_data.bin", b"\x01" + f_bytes(1, "chair") + f_bytes(3, body_data))
inst = lambda iid, q, t: f_bytes(1, iid) + f_bytes(2, pose(q, t))
put("requests", "set_poses.bin", b"\x02" + f_bytes(1, "scene-1") + f_bytes(2, inst("a", (1, 0, 0, 0), (0, 0, 0))) + f_bytes(2, inst("b", (0.7071067811865476, 0, 0.7071067811865476, 0), (1, 2, -3))))
pair = lambda k, a, b, cert, grad: f_varint(1, k) + f_bytes(2, a) + f_bytes(3, b) + f_varint(4, cert) + f_varint(5, grad)
put("requests", "batch_query.bin", b"\x03" + f_bytes(1, "scene-1") + f_bytes(2, pair(1, "a", "b", 1, 0)) + f_bytes(2, pair(2, "b", "a", 0, 1)))
packed_varints = lambda no, xs: f_bytes(no, b"".join(varint(x) for x in xs))
columns = f_varint(1, 3) + f_bytes(2, "a") + f_bytes(2, "b") + packed_varints(3, [0, 1]) + packed_varints(4, [1, 0]) + f_double(5, 0.05)
put("requests", "batch_columns.bin", b"\x03" + f_bytes(1, "scene-1") + f_bytes(3, columns))
collide = f_varint(1, 3) + f_bytes(2, "a") + f_bytes(3, "b") + f_double(6, 0.02)
state = f_bytes(1, inst("b", (1, 0, 0, 0), (0.3, 0, 0)))
put("requests", "query.bin", b"\x05" + f_bytes(1, "scene-1") + f_bytes(2, inst("a", (1, 0, 0, 0), (0, 0, 0))) + f_bytes(3, collide) + f_bytes(4, state) + f_varint(5, 7))
put("requests", "query_columns.bin", b"\x05" + f_bytes(1, "scene-1") + f_bytes(6, columns))
put("requests", "add_instance.bin", b"\x04" + f_bytes(1, "scene-1") + f_bytes(2, "body-1") + f_bytes(3, pose((1, 0, 0, 0), (0.5, 0, 0))))

total = sum(p.stat().st_size for p in SEEDS.rglob("*") if p.is_file())
print("wrote %d seeds, %d bytes" % (sum(1 for p in SEEDS.rglob("*") if p.is_file()), total))
