//! Triangle meshes from every format, and welding: the same mesh written as OFF, OBJ, binary and
//! ASCII STL and PLY gives the same welded triangles; a soup welds to its indexed mesh.

use super::*;
use sublevel_core::math::Real;
use sublevel_core::Error;

/// An axis-aligned box [0, 1] × [−0.5, 0.25] × [0.75, 2] (coordinates exact in f32): 8
/// vertices, 6 quads (outward), 12 triangles when each quad is split as the fan (a, b, c),
/// (a, c, d).
fn box_mesh() -> (Vec<[Real; 3]>, Vec<[u32; 4]>) {
    let (x, y, z) = ([0.0, 1.0], [-0.5, 0.25], [0.75, 2.0]);
    let v = (0..8).map(|k| [x[k & 1], y[(k >> 1) & 1], z[(k >> 2) & 1]]).collect();
    let quads = vec![[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    (v, quads)
}

fn fan(quads: &[[u32; 4]]) -> Vec<[u32; 3]> {
    quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect()
}

fn indexed_box() -> TriangleMesh {
    let (v, q) = box_mesh();
    TriangleMesh { vertices: v.iter().map(|p| Point3::from(*p)).collect(), triangles: fan(&q) }
}

/// The box as a triangle soup: every triangle its own three vertices (36).
fn soup_box() -> TriangleMesh {
    let m = indexed_box();
    let vertices = m.triangles.iter().flat_map(|t| t.map(|i| m.vertices[i as usize])).collect();
    let triangles = (0..m.triangles.len() as u32).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
    TriangleMesh { vertices, triangles }
}

/// Triangles as corner coordinates, each rotated to start at its smallest corner (orientation
/// kept), sorted: equal for meshes of the same triangles, whatever the vertex order.
fn triangle_set(m: &TriangleMesh) -> Vec<[[Real; 3]; 3]> {
    let mut out: Vec<[[Real; 3]; 3]> = m
        .triangles
        .iter()
        .map(|t| {
            let c = t.map(|i| {
                let p = m.vertices[i as usize];
                [p.x, p.y, p.z]
            });
            let first = (0..3).min_by(|&a, &b| c[a].partial_cmp(&c[b]).unwrap()).unwrap();
            [c[first], c[(first + 1) % 3], c[(first + 2) % 3]]
        })
        .collect();
    out.sort_by(|a, b| a.partial_cmp(b).unwrap());
    out
}

fn off_text() -> Vec<u8> {
    let (v, q) = box_mesh();
    let mut s = format!("OFF\n# a box\n{} {} 0\n", v.len(), q.len());
    for p in &v {
        s += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for f in &q {
        s += &format!("4 {} {} {} {} 255 0 0\n", f[0], f[1], f[2], f[3]);
    }
    s.into_bytes()
}

/// A soup OBJ of two objects: every triangle repeats its vertices, faces `v//vn` with negative
/// (relative) indices, and quads in the second object.
fn obj_text() -> Vec<u8> {
    let (v, q) = box_mesh();
    let mut s = String::from("# two objects\nmtllib box.mtl\no first\nvn 0 0 1\n");
    let tris = fan(&q[..3]);
    for t in &tris {
        for &i in t {
            s += &format!("v {} {} {}\n", v[i as usize][0], v[i as usize][1], v[i as usize][2]);
        }
        s += "f -3//1 -2//1 -1//1\n";
    }
    s += "o second\ng side\nusemtl red\n";
    let base = 3 * tris.len();
    for p in &v {
        s += &format!("v {} {} {} 1.0\n", p[0], p[1], p[2]);
    }
    for f in &q[3..] {
        let c = f.map(|i| base as u32 + i + 1);
        s += &format!("f {}/1/1 {}/1/1 {}/1/1 {}/1/1\n", c[0], c[1], c[2], c[3]);
    }
    s.into_bytes()
}

fn stl_triangles() -> Vec<[[f32; 3]; 3]> {
    let m = indexed_box();
    m.triangles.iter().map(|t| t.map(|i| m.vertices[i as usize].coords.map(|c| c as f32).into())).collect()
}

fn stl_binary_bytes() -> Vec<u8> {
    let mut out = vec![0u8; 80];
    let tris = stl_triangles();
    out.extend((tris.len() as u32).to_le_bytes());
    for t in &tris {
        out.extend([0f32; 3].iter().flat_map(|v| v.to_le_bytes()));
        for v in t {
            out.extend(v.iter().flat_map(|c| c.to_le_bytes()));
        }
        out.extend([0u8; 2]);
    }
    out
}

fn stl_ascii_bytes() -> Vec<u8> {
    let mut s = String::from("solid box\n");
    for t in stl_triangles() {
        s += "  facet normal 0 0 0\n    outer loop\n";
        for v in t {
            s += &format!("      vertex {} {} {}\n", v[0], v[1], v[2]);
        }
        s += "    endloop\n  endfacet\n";
    }
    s += "endsolid box\n";
    s.into_bytes()
}

fn ply_ascii_bytes() -> Vec<u8> {
    let (v, q) = box_mesh();
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        v.len(),
        q.len()
    );
    for p in &v {
        s += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for f in &q {
        s += &format!("4 {} {} {} {}\n", f[0], f[1], f[2], f[3]);
    }
    s.into_bytes()
}

/// Binary little-endian PLY: float vertices with an extra property, triangle faces with a
/// `uint` list and a trailing scalar.
fn ply_binary_bytes() -> Vec<u8> {
    let (v, q) = box_mesh();
    let tris = fan(&q);
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\ncomment made by a test\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nproperty uchar red\nelement face {}\n\
         property list uchar uint vertex_index\nproperty float quality\nend_header\n",
        v.len(),
        tris.len()
    )
    .into_bytes();
    for p in &v {
        for c in p {
            out.extend((*c as f32).to_le_bytes());
        }
        out.push(7);
    }
    for t in &tris {
        out.push(3);
        for i in t {
            out.extend(i.to_le_bytes());
        }
        out.extend(0.5f32.to_le_bytes());
    }
    out
}

#[test]
fn an_indexed_box_and_its_soup_weld_to_8_vertices_and_12_triangles() {
    let indexed = weld_mesh(&indexed_box(), DEFAULT_WELD_TOLERANCE).unwrap();
    assert_eq!((indexed.mesh.vertices.len(), indexed.mesh.triangles.len()), (8, 12));
    assert_eq!(indexed.mesh, indexed_box(), "an indexed mesh is left as it is");
    assert_eq!(indexed.report.merged_vertices, 0);
    let soup = soup_box();
    assert_eq!(soup.vertices.len(), 36);
    let welded = weld_mesh(&soup, DEFAULT_WELD_TOLERANCE).unwrap();
    assert_eq!((welded.mesh.vertices.len(), welded.mesh.triangles.len()), (8, 12));
    let r = &welded.report;
    assert_eq!((r.vertices_before, r.vertices_after, r.merged_vertices, r.unused_vertices), (36, 8, 28, 0));
    assert_eq!((r.triangles_before, r.triangles_after, r.degenerate_triangles, r.duplicate_triangles), (12, 12, 0, 0));
    // ε = 1e-9 × the box's diagonal √(1 + 0.75² + 1.25²).
    assert!((r.tolerance - 1e-9 * (1.0f64 + 0.5625 + 1.5625).sqrt()).abs() < 1e-18);
    assert_eq!(triangle_set(&welded.mesh), triangle_set(&indexed_box()));
    // Every soup vertex maps to the welded vertex at its position.
    for (v, w) in welded.source.iter().enumerate() {
        assert_eq!(welded.mesh.vertices[w.unwrap() as usize], soup.vertices[v]);
    }
}

#[test]
fn welding_drops_collapsed_and_repeated_triangles_and_merges_near_copies() {
    let mut m = soup_box();
    // A near copy of vertex 0 (1e-12 m away, under ε ≈ 1.9e-9 m) and a far one (1e-6 m).
    let near = m.vertices[0] + sublevel_core::math::Vector3::new(1e-12, 0.0, 0.0);
    let far = m.vertices[0] + sublevel_core::math::Vector3::new(1e-6, 0.0, 0.0);
    m.vertices.extend([near, far]);
    let (n0, f0) = (36, 37);
    // The first triangle again, reversed and through the near copy: a repeat.
    let t0 = m.triangles[0];
    m.triangles.push([t0[2], t0[1], n0]);
    // A triangle collapsed by the near copy: (v0, near, v1).
    m.triangles.push([t0[0], n0, t0[1]]);
    // A sliver through the far copy: kept (its corners stay distinct), far vertex kept.
    m.triangles.push([t0[0], f0, t0[1]]);
    // An unused vertex.
    m.vertices.push(Point3::new(9.0, 9.0, 9.0));
    let w = weld_mesh(&m, DEFAULT_WELD_TOLERANCE).unwrap();
    let r = &w.report;
    assert_eq!((r.vertices_before, r.vertices_after, r.merged_vertices, r.unused_vertices), (39, 9, 29, 1));
    assert_eq!((r.triangles_before, r.triangles_after, r.degenerate_triangles, r.duplicate_triangles), (15, 13, 1, 1));
    assert_eq!(w.source[38], None);
    assert_eq!(w.source[n0 as usize], w.source[t0[0] as usize]);
    // With τ = 0 only equal coordinates merge: the near copy stays, nothing collapses.
    let exact = weld_mesh(&m, 0.0).unwrap();
    assert_eq!(
        (exact.report.vertices_after, exact.report.degenerate_triangles, exact.report.duplicate_triangles),
        (10, 0, 0)
    );
    assert!(matches!(weld_mesh(&m, -1.0), Err(Error::InvalidArgument { field, .. }) if field == "weld_tolerance"));
    // Nothing left: every triangle collapsed.
    let flat = TriangleMesh { vertices: vec![Point3::origin(); 3], triangles: vec![[0, 1, 2]] };
    assert!(
        matches!(weld_mesh(&flat, DEFAULT_WELD_TOLERANCE), Err(Error::InvalidArgument { field, .. }) if field == "mesh")
    );
}

#[test]
fn every_format_gives_the_same_welded_triangles() {
    let want = triangle_set(&indexed_box());
    let files: [(&str, MeshFormat, Vec<u8>); 6] = [
        ("off", MeshFormat::Off, off_text()),
        ("obj", MeshFormat::Obj, obj_text()),
        ("binary stl", MeshFormat::Stl, stl_binary_bytes()),
        ("ascii stl", MeshFormat::Stl, stl_ascii_bytes()),
        ("ascii ply", MeshFormat::Ply, ply_ascii_bytes()),
        ("binary ply", MeshFormat::Ply, ply_binary_bytes()),
    ];
    for (name, format, bytes) in files {
        let m = load_triangle_mesh(&bytes, format, DEFAULT_MAX_MESH_POINTS).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(m.triangles.len(), 12, "{name}");
        let w = weld_mesh(&m, DEFAULT_WELD_TOLERANCE).unwrap();
        assert_eq!((w.mesh.vertices.len(), w.mesh.triangles.len()), (8, 12), "{name}");
        assert_eq!(triangle_set(&w.mesh), want, "{name}");
        assert_eq!(triangle_set(&m), want, "{name}: the triangles as read");
    }
    // The soup OBJ has 36 + 8 vertices as read (its two objects merged), the STLs 8 (stl_io
    // merges equal coordinates).
    let obj = load_triangle_mesh(&obj_text(), MeshFormat::Obj, DEFAULT_MAX_MESH_POINTS).unwrap();
    assert_eq!(obj.vertices.len(), 3 * 6 + 8);
    let stl = load_triangle_mesh(&stl_binary_bytes(), MeshFormat::Stl, DEFAULT_MAX_MESH_POINTS).unwrap();
    assert_eq!(stl.vertices.len(), 8);
}

fn expect_mesh_error<T: std::fmt::Debug>(r: Result<T>, needle: &str) {
    match r {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "mesh");
            assert!(reason.contains(needle), "`{reason}` lacks `{needle}`");
        }
        other => panic!("expected InvalidArgument(mesh), got {other:?}"),
    }
}

#[test]
fn meshes_without_faces_and_bad_faces_are_named() {
    let max = DEFAULT_MAX_MESH_POINTS;
    let cloud = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n";
    expect_mesh_error(load_triangle_mesh(cloud, MeshFormat::Ply, max), "no `face` element");
    expect_mesh_error(load_triangle_mesh(b"v 0 0 0\nv 1 0 0\n", MeshFormat::Obj, max), "no `f` lines");
    expect_mesh_error(load_triangle_mesh(b"OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", MeshFormat::Off, max), "no faces");
    expect_mesh_error(load_triangle_mesh(b"0 0 0\n", MeshFormat::Xyz, max), "point cloud");
    expect_mesh_error(load_triangle_mesh(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", MeshFormat::Obj, max), "line 4");
    expect_mesh_error(load_triangle_mesh(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", MeshFormat::Obj, max), "1-based");
    expect_mesh_error(
        load_triangle_mesh(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 -2 -1\n", MeshFormat::Obj, max),
        "names no vertex",
    );
    expect_mesh_error(load_triangle_mesh(b"v 0 0 0\nv 1 0 0\nf 1 2\n", MeshFormat::Obj, max), "at least 3");
    let bad_index = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n";
    expect_mesh_error(load_triangle_mesh(bad_index, MeshFormat::Ply, max), "names vertex 3");
    let float_lists = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar float vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    expect_mesh_error(load_triangle_mesh(float_lists, MeshFormat::Ply, max), "must list integers");
    // A lying binary STL count still fails before allocating.
    let mut stl = stl_binary_bytes();
    stl[80] = 200;
    expect_mesh_error(load_triangle_mesh(&stl, MeshFormat::Stl, max), "stl");
    // Limits as for points.
    assert!(matches!(load_triangle_mesh(&off_text(), MeshFormat::Off, 4), Err(Error::ResourceExhausted(_))));
    assert!(matches!(load_triangle_mesh(&obj_text(), MeshFormat::Obj, 10), Err(Error::ResourceExhausted(_))));
    // A file error names the path.
    let missing = std::path::Path::new("/nonexistent/link.stl");
    let e = load_triangle_mesh_file(missing, None, max).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/link.stl"), "{e}");
}
