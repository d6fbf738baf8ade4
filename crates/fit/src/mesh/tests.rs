//! Every format against hand-written files, the lying headers that must fail before anything is
//! allocated, the limits, and the bundled PSB chair and fuzz seeds.

use super::limits::{foreign_message, FOREIGN_MESSAGE_BYTES};
use super::ply::{MAX_PLY_ELEMENTS, MAX_PLY_PROPERTIES};
use super::*;
use sublevel_core::Error;

/// The format by name (the text the CLI and the wire send), then [`super::parse_points`].
fn parse_points(bytes: &[u8], format: &str) -> Result<Vec<Point3>> {
    super::parse_points(bytes, format.parse()?)
}

/// The format by name, then [`super::parse_points_limited`].
fn parse_points_limited(bytes: &[u8], format: &str, max_points: usize) -> Result<Vec<Point3>> {
    super::parse_points_limited(bytes, format.parse()?, max_points)
}

#[test]
fn format_names_round_trip() {
    for f in MeshFormat::ALL {
        assert_eq!(f.name().parse::<MeshFormat>().unwrap(), f);
        assert_eq!(f.name().to_uppercase().parse::<MeshFormat>().unwrap(), f);
    }
    assert_eq!(".PTS".parse::<MeshFormat>().unwrap(), MeshFormat::Xyz);
    assert_eq!(MeshFormat::of_path(std::path::Path::new("a/chair.Off")).unwrap(), MeshFormat::Off);
    assert!(MeshFormat::of_path(std::path::Path::new("no_extension")).is_err());
}

fn expect_mesh_error(r: Result<Vec<Point3>>, needle: &str) {
    match r {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "mesh");
            assert!(reason.contains(needle), "`{reason}` lacks `{needle}`");
        }
        other => panic!("expected InvalidArgument(mesh), got {other:?}"),
    }
}

/// `ResourceExhausted` naming `mesh` and containing `needle`.
fn expect_exhausted(r: Result<Vec<Point3>>, needle: &str) {
    match r {
        Err(Error::ResourceExhausted(msg)) => {
            assert!(msg.starts_with("`mesh`: "), "`{msg}` does not name `mesh`");
            assert!(msg.contains(needle), "`{msg}` lacks `{needle}`");
        }
        other => panic!("expected ResourceExhausted(mesh), got {other:?}"),
    }
}

/// A plain sentence: no Rust `Debug` wrappers, no escaped quotes, no multi-line dumps.
fn assert_plain(e: &Error) {
    let msg = e.to_string();
    for bad in ["Custom {", "kind:", "Error {", "[\"", "\\\"", "\n", "\t", "Some(", "ParseFloatError"] {
        assert!(!msg.contains(bad), "`{msg}` contains `{bad}`");
    }
}

#[test]
fn off_parses_and_reports_line_numbers() {
    let off = b"OFF\n# a comment\n4 1 0\n0 0 0\n1 0 0\n0 1.5 0\n0 0 -2e-1\n3 0 1 2\n";
    let p = parse_points(off, "off").unwrap();
    assert_eq!(
        p,
        vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.5, 0.0),
            Point3::new(0.0, 0.0, -0.2)
        ]
    );
    // Counts on the header line.
    assert_eq!(parse_points(b"OFF 1 0 0\n1 2 3\n", ".OFF").unwrap(), vec![Point3::new(1.0, 2.0, 3.0)]);
    expect_mesh_error(parse_points(b"OFF\n2 0 0\n1 2 3\n4 x 6\n", "off"), "off line 4: `x` is not a number");
    expect_mesh_error(parse_points(b"OFF\n3 0 0\n1 2 3\n", "off"), "ends after 1 of 3 vertices");
    expect_mesh_error(parse_points(b"PLY\n", "off"), "off line 1: expected header");
    expect_mesh_error(parse_points(b"OFF\nfoo\n", "off"), "off line 2");
    expect_mesh_error(parse_points(b"OFF\n1 0 0\n1 2\n", "off"), "off line 3: expected 3 coordinates");
    expect_mesh_error(parse_points(b"OFF\n1 0 0\n1 2 inf\n", "off"), "not finite");
    expect_mesh_error(parse_points(b"", "off"), "empty");
    expect_mesh_error(parse_points(&[0xff, 0xfe, 0x00], "off"), "UTF-8");
}

#[test]
fn xyz_parses_and_reports_line_numbers() {
    let p = parse_points(b"1 2 3\n\n4,5,6 0 0 1\n# end\n", "xyz").unwrap();
    assert_eq!(p, vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)]);
    expect_mesh_error(parse_points(b"1 2 3\n1 2\n", "xyz"), "xyz line 2");
    expect_mesh_error(parse_points(b"\n\n", "xyz"), "no vertices");
}

#[test]
fn obj_parses_vertices() {
    let obj = b"# cube corner\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1.25\nf 1 2 3\nf 1 2 4\n";
    let p = parse_points(obj, "OBJ").unwrap();
    assert_eq!(p.len(), 4);
    assert_eq!(p[3], Point3::new(0.0, 0.0, 1.25));
    expect_mesh_error(parse_points(b"v 1 2 zz\n", "obj"), "obj");
}

fn stl_binary(tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
    let mut out = vec![0u8; 80];
    out.extend((tris.len() as u32).to_le_bytes());
    for t in tris {
        out.extend([0f32; 3].iter().flat_map(|v| v.to_le_bytes()));
        for v in t {
            out.extend(v.iter().flat_map(|c| c.to_le_bytes()));
        }
        out.extend([0u8; 2]);
    }
    out
}

#[test]
fn stl_ascii_and_binary_parse() {
    let ascii = b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 2 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 0 3\nendloop\nendfacet\nendsolid t\n";
    let mut p = parse_points(ascii, "stl").unwrap();
    p.sort_by(|a, b| a.coords.iter().partial_cmp(b.coords.iter()).unwrap());
    assert_eq!(
        p,
        vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.0, 0.0, 3.0),
            Point3::new(0.0, 2.0, 0.0),
            Point3::new(1.0, 0.0, 0.0)
        ]
    );
    let bin = stl_binary(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]]);
    let mut q = parse_points(&bin, "stl").unwrap();
    q.sort_by(|a, b| a.coords.iter().partial_cmp(b.coords.iter()).unwrap());
    assert_eq!(q, vec![Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 2.0, 0.0), Point3::new(1.0, 0.0, 0.0)]);
    // Truncated binary: header promises 5 triangles, holds 1.
    let mut bad = bin.clone();
    bad[80] = 5;
    expect_mesh_error(parse_points(&bad, "stl"), "stl");
    expect_mesh_error(parse_points(b"solid x\nfacet normal 0 0\n", "stl"), "stl");
}

#[test]
fn ply_ascii_and_binary_parse() {
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0.5\n0 2 -1\n3 0 1 2\n";
    let p = parse_points(ascii, "ply").unwrap();
    assert_eq!(p, vec![Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.5), Point3::new(0.0, 2.0, -1.0)]);
    let mut bin =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
            .to_vec();
    for v in [1.0f32, 2.0, 3.0, -4.0, 0.5, 6.0] {
        bin.extend(v.to_le_bytes());
    }
    let q = parse_points(&bin, "ply").unwrap();
    assert_eq!(q, vec![Point3::new(1.0, 2.0, 3.0), Point3::new(-4.0, 0.5, 6.0)]);
    expect_mesh_error(parse_points(b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2\n", "ply"), "ply");
    expect_mesh_error(
        parse_points(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
            "ply",
        ),
        "missing property `z`",
    );
    expect_mesh_error(parse_points(b"not a ply", "ply"), "ply");
}

#[test]
fn unknown_format_is_named() {
    expect_mesh_error(parse_points(b"1 2 3", "vtk"), "unknown format `vtk`");
}

fn ply_binary(format: &str, header_body: &str, payload: &[u8]) -> Vec<u8> {
    let mut out = format!("ply\nformat {format} 1.0\n{header_body}end_header\n").into_bytes();
    out.extend_from_slice(payload);
    out
}

#[test]
fn ply_lying_headers_fail_before_allocating() {
    // The 64-byte probe: 10^15 vertices promised, none present (ply-rs alone would allocate without bound).
    let probe = b"ply\nformat ascii 1.0\nelement vertex 1000000000000000\nend_header\n";
    assert_eq!(probe.len(), 64);
    expect_mesh_error(
        parse_points(probe, "ply"),
        "ply header declares 1000000000000000 vertices but the file has 0 bytes after its header \
         (at least 1 byte per vertex)",
    );
    let xyz = "element vertex 1000000000000000\nproperty float x\nproperty float y\nproperty float z\n";
    for format in ["binary_little_endian", "binary_big_endian"] {
        let bin = ply_binary(format, xyz, &[0u8; 12]);
        expect_mesh_error(
            parse_points(&bin, "ply"),
            "ply header declares 1000000000000000 vertices but the file has 12 bytes after its header \
             (at least 12 bytes per vertex)",
        );
        // A property-less element of huge count costs nothing in binary, but any other lying
        // element is caught too, not only `vertex`.
        let faces = format!("{xyz}element face 4000000000\nproperty list uchar int vertex_indices\n")
            .replace("1000000000000000", "1");
        expect_mesh_error(
            parse_points(&ply_binary(format, &faces, &[0u8; 12]), "ply"),
            "ply header declares 4000000000 `face` elements but the file has 12 bytes after its header \
             (at least 1 byte per `face` element)",
        );
    }
    let ascii = "ply\nformat ascii 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty \
                 float z\nend_header\n0 0 0\n";
    expect_mesh_error(
        parse_points(ascii.as_bytes(), "ply"),
        "ply header declares 1000 vertices but the file has 6 bytes after its header (at least 6 bytes per vertex)",
    );
    // u64 overflow in a count is a plain error, not a panic.
    expect_mesh_error(
        parse_points(b"ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\nend_header\n", "ply"),
        "ply line 3: element count `99999999999999999999999` is not an integer",
    );
    // Elements that fit one by one but not together.
    let two = ply_binary(
        "binary_little_endian",
        "element vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement extra 10\n\
         property double w\n",
        &[0u8; 80],
    );
    expect_mesh_error(parse_points(&two, "ply"), "need at least 92 bytes but the file has 80 bytes");
}

#[test]
fn ply_header_is_bounded_and_checked() {
    let mut long = b"ply\nformat ascii 1.0\n".to_vec();
    while long.len() <= MAX_PLY_HEADER_BYTES {
        long.extend_from_slice(b"comment padding padding padding padding padding padding\n");
    }
    long.extend_from_slice(b"end_header\n");
    expect_mesh_error(parse_points(&long, "ply"), "ply header is longer than 65536 bytes");
    let mut many = String::from("ply\nformat ascii 1.0\n");
    for k in 0..=MAX_PLY_ELEMENTS {
        many.push_str(&format!("element e{k} 0\n"));
    }
    many.push_str("end_header\n");
    expect_mesh_error(parse_points(many.as_bytes(), "ply"), "more than 64 elements");
    let mut props = String::from("ply\nformat ascii 1.0\nelement vertex 0\n");
    for k in 0..=MAX_PLY_PROPERTIES {
        props.push_str(&format!("property float p{k}\n"));
    }
    props.push_str("end_header\n");
    expect_mesh_error(parse_points(props.as_bytes(), "ply"), "more than 256 properties");
    for (header, needle) in [
        ("element vertex 1\nelement vertex 2\n", "ply line 4: element `vertex` is declared twice"),
        ("property float x\n", "ply line 3: `property` before any `element`"),
        ("element face 1\nproperty list float int idx\n", "list length must have an integer type, not `float`"),
        ("element vertex 1\nproperty float128 x\n", "unknown property type `float128`"),
        ("element vertex 1\nproperty float x\nproperty float x\n", "property `x` is declared twice"),
        ("elephant 3\n", "ply line 3: unexpected header line starting with `elephant`"),
        ("format binary_big_endian 1.0\n", "a second, different `format` line"),
    ] {
        let ply = format!("ply\nformat ascii 1.0\n{header}end_header\n");
        expect_mesh_error(parse_points(ply.as_bytes(), "ply"), needle);
    }
    expect_mesh_error(
        parse_points(b"ply\nformat ascii 1.0\nelement vertex 1\n", "ply"),
        "ends before its `end_header`",
    );
    expect_mesh_error(parse_points(b"ply\nelement vertex 0\nend_header\n", "ply"), "no `format` line");
    expect_mesh_error(parse_points(b"ply\nformat ascii\nend_header\n", "ply"), "ply line 2: expected a version");
    expect_mesh_error(parse_points(b"ply\nformat ascii 1.0\nend_header\n", "ply"), "no `vertex` element");
}

#[test]
fn ply_binary_elements_lists_and_types_parse() {
    // Big endian, mixed scalar types, a face list before the vertices, an extra vertex column.
    let header = "element face 2\nproperty list uchar int vertex_indices\nelement vertex 2\nproperty short x\n\
                  property double y\nproperty uchar red\nproperty float z\n";
    let mut payload = vec![3u8];
    payload.extend([0i32, 1, 1].iter().flat_map(|v| v.to_be_bytes()));
    payload.push(0u8); // an empty list
    for (x, y, r, z) in [(-3i16, 0.25f64, 7u8, 1.5f32), (4, -2.0, 255, 0.0)] {
        payload.extend(x.to_be_bytes());
        payload.extend(y.to_be_bytes());
        payload.push(r);
        payload.extend(z.to_be_bytes());
    }
    let p = parse_points(&ply_binary("binary_big_endian", header, &payload), "ply").unwrap();
    assert_eq!(p, vec![Point3::new(-3.0, 0.25, 1.5), Point3::new(4.0, -2.0, 0.0)]);
    // Truncated inside the vertices; a list running past the end; a negative list length.
    let cut = &payload[..payload.len() - 2];
    expect_mesh_error(
        parse_points(&ply_binary("binary_big_endian", header, cut), "ply"),
        "malformed ply file: the data ends inside vertex 2 of 2",
    );
    let mut long_list = payload.clone();
    long_list[0] = 200;
    expect_mesh_error(
        parse_points(&ply_binary("binary_big_endian", header, &long_list), "ply"),
        "the data ends inside `face` element 1 of 2",
    );
    let signed = header.replace("list uchar", "list char");
    let mut negative = payload.clone();
    negative[0] = 0xff;
    expect_mesh_error(
        parse_points(&ply_binary("binary_big_endian", &signed, &negative), "ply"),
        "`face` element 1: list `vertex_indices` has negative length -1",
    );
    // CRLF header, property-less element, comments.
    let crlf = "ply\r\nformat ascii 1.0\r\ncomment hi\r\nelement empty 2\r\nelement vertex 1\r\nproperty int x\r\n\
                property int y\r\nproperty list uchar float z\r\nend_header\r\n\r\n\r\n1 2 1 3.5\r\n";
    expect_mesh_error(parse_points(crlf.as_bytes(), "ply"), "ply vertex property `z` is a list");
    let crlf = crlf.replace("list uchar float z", "float z").replace("1 2 1 3.5", "1 2 3.5");
    assert_eq!(parse_points(crlf.as_bytes(), "ply").unwrap(), vec![Point3::new(1.0, 2.0, 3.5)]);
}

#[test]
fn ply_ascii_errors_name_the_line() {
    let head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let ok = format!("{head}0 0 0\n1 1 1\n2 0 1\n");
    assert_eq!(parse_points(ok.as_bytes(), "ply").unwrap().len(), 2);
    for (body, needle) in [
        ("0 0 0\n1 x 1\n2 0 1\n", "malformed ply file: line 11: `x` is not a valid float (property `y` of vertex)"),
        ("0 0 0\n1 1\n2 0 1\n", "malformed ply file: line 11: too few values for vertex (nothing for property `z`)"),
        ("0 0 0\n1 1 1\n3 0 1\n", "line 12: too few values for `face` element (nothing for property `vertex_indices`)"),
        ("0 0 0\n1 1 1\n300 0 1\n", "line 12: `300` is not a valid uchar"),
        ("0 0 0      \n1 1 1", "malformed ply file: the file ends after 0 of 1 `face` element"),
    ] {
        let ply = format!("{head}{body}");
        let r = parse_points(ply.as_bytes(), "ply");
        if let Err(e) = &r {
            assert_plain(e);
        }
        expect_mesh_error(r, needle);
    }
}

#[test]
fn off_and_stl_lying_headers_fail_before_allocating() {
    expect_mesh_error(
        parse_points(b"OFF\n1000000000000 0 0\n0 0 0\n", "off"),
        "off file ends after 1 of 1000000000000 vertices (1000000000000 vertices need at least 6000000000000 \
         bytes after the counts line, the file has 6)",
    );
    expect_mesh_error(
        parse_points(b"OFF 3 0 0\n0 0 0\n", "off"),
        "off file ends after 1 of 3 vertices (3 vertices need at least 18 bytes after the counts line, the file has 6)",
    );
    // A lie beyond usize and beyond max_points is still InvalidArgument (the file is malformed).
    expect_mesh_error(
        parse_points_limited(b"OFF 18446744073709551615 0 0\n", "off", 3),
        "off file ends after 0 of 18446744073709551615 vertices",
    );
    // The last line may lack its newline.
    assert_eq!(parse_points(b"OFF 2 0 0\n0 0 0\n1 1 1", "off").unwrap().len(), 2);
    let mut bin = stl_binary(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]]);
    bin[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    expect_mesh_error(
        parse_points(&bin, "stl"),
        "stl header declares 4294967295 triangles but the file has 50 bytes after its 84-byte header \
         (50 bytes per triangle)",
    );
    expect_mesh_error(parse_points(&[0u8; 83], "stl"), "stl file has 83 bytes: too short for a binary stl");
}

#[test]
fn counts_above_max_points_are_resource_exhausted() {
    let max = 3;
    expect_exhausted(
        parse_points_limited(b"OFF\n4 0 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n", "off", max),
        "the off header declares 4 vertices, which exceeds the limit of 3 points",
    );
    expect_exhausted(
        parse_points_limited(b"0 0 0\n1 0 0\n# x\n0 1 0\n0 0 1\n", "xyz", max),
        "the xyz file has 4 point lines, which exceeds the limit of 3 points",
    );
    expect_exhausted(
        parse_points_limited(b"v 0 0 0\nv 1 0 0\n  v\t0 1 0\nv 0 0 1\nvn 0 0 1\nf 1 2 3\n", "obj", max),
        "the obj file has 4 `v` lines, which exceeds the limit of 3 points",
    );
    let ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
               end_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
    expect_exhausted(
        parse_points_limited(ply.as_bytes(), "ply", max),
        "the ply header declares 4 vertices, which exceeds the limit of 3 points",
    );
    let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    // 10 triangles > 3 × 3: rejected from the header; 2 triangles with 4 distinct vertices:
    // rejected after merging.
    expect_exhausted(
        parse_points_limited(&stl_binary(&[tri; 10]), "stl", max),
        "the stl header declares 10 triangles, more than 3 × the limit of 3 points",
    );
    let two = stl_binary(&[tri, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]);
    expect_exhausted(
        parse_points_limited(&two, "stl", max),
        "the stl file has 4 vertices, which exceeds the limit of 3 points",
    );
    let facet = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n";
    let ascii = format!("solid t\n{}endsolid t\n", facet.repeat(10));
    expect_exhausted(parse_points_limited(ascii.as_bytes(), "stl", max), "the stl file has 10 triangles");
    // Within the limit everything still parses.
    assert_eq!(parse_points_limited(&stl_binary(&[tri; 9]), "stl", max).unwrap().len(), 3);
    assert_eq!(parse_points_limited(b"OFF 3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "off", max).unwrap().len(), 3);
}

#[test]
fn third_party_errors_are_plain_sentences() {
    let cases: [(&[u8], &str, &str); 5] = [
        (b"solid x\nfacet normal 0 0\n", "stl", "malformed stl file: invalid facet header: `facet normal 0 0`"),
        (
            b"solid x\nfacet normal 0 0 1\nouter lop\n",
            "stl",
            "malformed stl file: expected `outer loop`, got `outer lop`",
        ),
        (b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 1 2 q\n", "stl", "malformed stl file: invalid float"),
        (b"v 1 2 3\nv 1 2 zz\n", "obj", "obj line 2: `zz` is not a number"),
        (b"v 1 2 3\nv 1 2 3 0\n", "obj", "obj line 2: the weight w is 0"),
    ];
    for (bytes, fmt, needle) in cases {
        let r = parse_points(bytes, fmt);
        if let Err(e) = &r {
            assert_plain(e);
        }
        expect_mesh_error(r, needle);
    }
    assert_eq!(foreign_message(r#"got ["a\"b", "c"] and []"#), "got `a\"b c` and ``");
    assert_eq!(foreign_message("[not a list"), "[not a list");
    let long = format!("expected [\"{}\"]", "x".repeat(1000));
    assert!(foreign_message(&long).len() <= FOREIGN_MESSAGE_BYTES + '…'.len_utf8());
    expect_mesh_error(parse_points(b"1 2 3", &"v".repeat(1000)), "unknown format `vvvvv");
    assert!(parse_points(b"1 2 3", &"v".repeat(1000)).unwrap_err().to_string().len() < 200);
}

#[test]
fn psb_chair_parses_with_its_header_count() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join("data/psb/chair_101.off");
    let p = load_points(&path).unwrap();
    assert_eq!(p.len(), 8499);
    assert_eq!(p[0], Point3::new(0.25249, 0.800481, 0.386195));
    // The same bytes under a limit just below and at the count.
    let bytes = std::fs::read(&path).unwrap();
    expect_exhausted(parse_points_limited(&bytes, "off", 8498), "declares 8499 vertices");
    assert_eq!(parse_points_limited(&bytes, "off", 8499).unwrap().len(), 8499);
}

#[test]
fn fuzz_seeds_parse() {
    // The committed seed corpora of the mesh fuzz targets (fuzz/seeds/mesh_*) are valid files.
    let seeds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join("fuzz/seeds");
    let mut n = 0;
    for fmt in ["off", "obj", "stl", "ply", "xyz"] {
        for entry in std::fs::read_dir(seeds.join(format!("mesh_{fmt}"))).unwrap() {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            let p = parse_points_limited(&bytes, fmt, 100_000).unwrap_or_else(|e| panic!("{path:?}: {e}"));
            assert!(!p.is_empty());
            n += 1;
        }
    }
    assert!(n >= 10, "{n} seeds");
}

#[test]
fn obj_reads_every_v_line_and_skips_the_rest() {
    // A point cloud without faces (tobj returned no positions for it).
    let cloud = b"v 0 0 0\nv 1 0 0\r\nv 0 1 0 # comment\n\tv 0 0 2 2\nv 1 1 1 0.5 0.5 0.5\n";
    assert_eq!(
        parse_points(cloud, "obj").unwrap(),
        vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(1.0, 1.0, 1.0)
        ]
    );
    // Faces, normals and texture coordinates are not read: out-of-range or overflowing
    // relative indices (a tobj panic found by fuzzing, fuzz/regressions/mesh_obj) do no harm.
    let faces = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/-9223372036854775807 2/-6/1 3//-4\nf 1 7 -9\n";
    assert_eq!(parse_points(faces, "obj").unwrap().len(), 3);
    let crash = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join("fuzz/regressions/mesh_obj/tobj-normal-index-overflow.obj");
    let _ = parse_points_limited(&std::fs::read(crash).unwrap(), "obj", 100_000);
    expect_mesh_error(parse_points(b"vt 0 0\nf 1 2 3\n", "obj"), "the obj file has no vertices");
}

#[test]
fn off_mesh_reads_faces_as_triangle_fans() {
    // A quad (fanned into 2 triangles), a triangle with a color, a degenerate 2-vertex face.
    let off = b"OFF\n# quad\n5 3 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n4 0 1 2 3\n3 0 1 4 255 0 0\n2 0 1\n";
    let m = parse_off_mesh(off, 100).unwrap();
    assert_eq!(m.vertices.len(), 5);
    assert_eq!(m.vertices[4], Point3::new(0.0, 0.0, 1.0));
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
    // The points-only path reads the same vertices and never looks at the faces.
    assert_eq!(parse_points(off, "off").unwrap(), m.vertices);
    let bad_faces = b"OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n";
    assert_eq!(parse_points(bad_faces, "off").unwrap().len(), 3);
    expect_mesh_error(
        parse_off_mesh(bad_faces, 100).map(|m| m.vertices),
        "off line 5: `7` is not a vertex index (the file has 3 vertices)",
    );
    for (text, needle) in [
        (&b"OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n"[..], "off line 5: the face has 2 of its 3 vertex indices"),
        (b"OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\nx 0 1 2\n", "off line 5: expected a face"),
        (b"OFF 3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "off file ends after 1 of 2 faces"),
        (b"OFF 0 0 0\n", "the off file has no vertices"),
    ] {
        expect_mesh_error(parse_off_mesh(text, 100).map(|m| m.vertices), needle);
    }
    // A lying face count reserves nothing and names where the file ends.
    expect_mesh_error(
        parse_off_mesh(b"OFF 1 1000000000000 0\n0 0 0\n3 0 0 0\n", 100).map(|m| m.vertices),
        "off file ends after 1 of 1000000000000 faces (1000000000000 faces need at least 2000000000000 bytes after \
         the vertices, the file has 8)",
    );
    // The vertex limits are those of the points-only path.
    expect_exhausted(
        parse_off_mesh(b"OFF\n4 0 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n", 3).map(|m| m.vertices),
        "the off header declares 4 vertices, which exceeds the limit of 3 points",
    );
}

#[test]
fn psb_chair_mesh_has_its_declared_faces() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join("data/psb/chair_101.off");
    let bytes = std::fs::read(&path).unwrap();
    let m = parse_off_mesh(&bytes, DEFAULT_MAX_MESH_POINTS).unwrap();
    assert_eq!(m.vertices, load_points(&path).unwrap());
    assert_eq!(m.triangles.len(), 16998);
    assert_eq!(m.triangles[16997], [1232, 949, 1234]);
}
