//! Unit tests of the sensor-file readers: small PCD (ASCII, binary, binary_compressed), PLY, XYZ
//! and 16-bit PNG files written in a temporary directory read back to the points and depths
//! written, and malformed files fail naming the file and what is wrong.

use super::*;
use std::path::PathBuf;

const POINTS: [[f32; 3]; 3] = [[0.5, -0.25, 1.0], [1.5, 2.0, -3.25], [0.125, 0.0, 4.0]];

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn points(frame: FileFrame) -> Vec<[f32; 3]> {
    match frame {
        FileFrame::Points(p) => p,
        other => panic!("expected points, got {other:?}"),
    }
}

fn invalid_reason(e: Error) -> (String, String) {
    match e {
        Error::InvalidArgument { field, reason } => (field, reason),
        other => panic!("expected an invalid argument, got {other}"),
    }
}

/// A binary PCD header of fields x y z intensity (float) and ring (uint16).
fn binary_header(data: &str, n: usize) -> String {
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity ring\n\
         SIZE 4 4 4 4 2\nTYPE F F F F U\nCOUNT 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\n\
         VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )
}

#[test]
fn an_ascii_pcd_reads_its_coordinates_skipping_the_other_fields_and_keeping_nan_holes() {
    let dir = tempfile::tempdir().unwrap();
    let text = "# .PCD v0.7\nVERSION 0.7\nFIELDS rgb x y z normal\nSIZE 4 4 4 8 4\nTYPE F F F F F\n\
                COUNT 1 1 1 1 3\nWIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n\
                4.2108e+06 0.5 -0.25 1.0 0 0 1\n\
                0 1.5 2 -3.25 0 0 1\n\
                \n\
                7 0.125 0 4 1 0 0\n\
                7 nan nan nan 1 0 0\n";
    let got = points(read_frame(&write(&dir, "cloud.pcd", text.as_bytes())).unwrap());
    assert_eq!(got.len(), 4);
    assert_eq!(&got[..3], &POINTS);
    assert!(got[3].iter().all(|v| v.is_nan()));
}

#[test]
fn a_binary_pcd_reads_its_records() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = binary_header("binary", POINTS.len()).into_bytes();
    for (k, p) in POINTS.iter().enumerate() {
        for v in p.iter().chain(&[100.0 + k as f32]) {
            bytes.extend(v.to_le_bytes());
        }
        bytes.extend((k as u16).to_le_bytes());
    }
    assert_eq!(points(read_frame(&write(&dir, "cloud.PCD", &bytes)).unwrap()), POINTS);

    // One byte short of the last record.
    bytes.pop();
    let (field, reason) = invalid_reason(read_frame(&write(&dir, "short.pcd", &bytes)).unwrap_err());
    assert!(field.ends_with("short.pcd"), "{field}");
    assert!(reason.contains("3 points of 18 bytes"), "{reason}");
}

/// Literal-only LZF: runs of at most 32 bytes, each after its control byte (length − 1).
fn lzf_literals(plain: &[u8]) -> Vec<u8> {
    plain.chunks(32).flat_map(|c| std::iter::once(c.len() as u8 - 1).chain(c.iter().copied())).collect()
}

#[test]
fn a_binary_compressed_pcd_reads_its_fields_stored_one_after_another() {
    let dir = tempfile::tempdir().unwrap();
    // Fields in turn: every point's x, then y, then z (doubles here), then intensity, then ring.
    let mut plain = Vec::new();
    for p in &POINTS {
        plain.extend(p[0].to_le_bytes());
    }
    for p in &POINTS {
        plain.extend(p[1].to_le_bytes());
    }
    for p in &POINTS {
        plain.extend(f64::from(p[2]).to_le_bytes());
    }
    plain.extend([0u8; 3 * 4 + 3 * 2]);
    let header = binary_header("binary_compressed", POINTS.len()).replace("SIZE 4 4 4 4 2", "SIZE 4 4 8 4 2");
    let compressed = lzf_literals(&plain);
    let mut bytes = header.into_bytes();
    bytes.extend((compressed.len() as u32).to_le_bytes());
    bytes.extend((plain.len() as u32).to_le_bytes());
    bytes.extend(&compressed);
    assert_eq!(points(read_frame(&write(&dir, "cloud.pcd", &bytes)).unwrap()), POINTS);
}

#[test]
fn lzf_back_references_repeat_earlier_output_and_corrupt_data_fails() {
    // "abc", then 6 bytes from 3 back: "abcabcabc".
    let input = [2, b'a', b'b', b'c', 4 << 5, 2];
    assert_eq!(lzf_decompress(&input, 9).unwrap(), b"abcabcabc");
    // A long reference: length 7 + 3 + 2 = 12 bytes of "x".
    let input = [0, b'x', 7 << 5, 3, 0];
    assert_eq!(lzf_decompress(&input, 13).unwrap(), vec![b'x'; 13]);
    for (input, size) in [(&[2u8, b'a', b'b', b'c', 4 << 5, 9][..], 9), (&[2, b'a', b'b'][..], 3), (&[0, b'a'][..], 2)]
    {
        let (field, _) = invalid_reason(lzf_decompress(input, size).unwrap_err());
        assert_eq!(field, "pcd");
    }
}

#[test]
fn malformed_pcd_headers_and_data_fail_naming_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let head = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n";
    let cases = [
        ("FIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nDATA ascii\n1 2\n", "no `z` field"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F I\nWIDTH 1\nDATA ascii\n1 2 3\n", "field `z` must be one float"),
        ("FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n1 2 3\n", "SIZE: 2 values for the 3 FIELDS"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 3\nDATA ascii\n", "POINTS 3 differs"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA lzma\n", "DATA: expected ascii"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\n", "ends before its DATA line"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 99999999\nHEIGHT 99999999\nDATA binary\n", "exceeds the limit"),
        (&format!("{head}1 2\n"), "point 0: 2 values, the fields take 3"),
        (&format!("{head}1 2 zz\n"), "`zz` (z) is not a number"),
        (&format!("{head}\n"), "ends after 0 points"),
    ];
    for (text, expected) in cases {
        let (field, reason) = invalid_reason(read_frame(&write(&dir, "bad.pcd", text.as_bytes())).unwrap_err());
        assert!(field.ends_with("bad.pcd"), "{field}");
        assert!(reason.contains(expected), "{text:?}: {reason}");
    }
    // An empty cloud is valid.
    let empty = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nDATA binary\n";
    assert!(points(read_frame(&write(&dir, "empty.pcd", empty.as_bytes())).unwrap()).is_empty());
}

#[test]
fn ply_and_xyz_files_read_their_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let mut ascii = String::from("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n");
    ascii.push_str("property float z\nproperty uchar red\nend_header\n");
    for p in &POINTS {
        ascii.push_str(&format!("{} {} {} 255\n", p[0], p[1], p[2]));
    }
    assert_eq!(points(read_frame(&write(&dir, "cloud.ply", ascii.as_bytes())).unwrap()), POINTS);

    let header = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
                  property double z\nend_header\n";
    let mut binary = header.as_bytes().to_vec();
    for v in POINTS.iter().flatten() {
        binary.extend(f64::from(*v).to_le_bytes());
    }
    assert_eq!(points(read_frame(&write(&dir, "cloud.ply", &binary)).unwrap()), POINTS);
    binary.truncate(binary.len() - 4);
    let (field, _) = invalid_reason(read_frame(&write(&dir, "short.ply", &binary)).unwrap_err());
    assert!(field.ends_with("short.ply"), "{field}");

    let xyz: String = POINTS.iter().map(|p| format!("{} {} {}\n", p[0], p[1], p[2])).collect();
    assert_eq!(points(read_frame(&write(&dir, "cloud.xyz", xyz.as_bytes())).unwrap()), POINTS);
}

fn png_bytes(width: u32, height: u32, depth: png::BitDepth, samples: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(depth);
    encoder.write_header().unwrap().write_image_data(samples).unwrap();
    out
}

#[test]
fn a_16_bit_png_reads_as_a_depth_image_and_other_pngs_fail() {
    let dir = tempfile::tempdir().unwrap();
    let depths: Vec<u16> = vec![0, 1000, 65535, 1234, 2, 40000];
    let samples: Vec<u8> = depths.iter().flat_map(|d| d.to_be_bytes()).collect();
    let path = write(&dir, "depth.png", &png_bytes(3, 2, png::BitDepth::Sixteen, &samples));
    assert_eq!(read_frame(&path).unwrap(), FileFrame::Depth { width: 3, height: 2, pixels: depths });

    let path = write(&dir, "gray8.png", &png_bytes(3, 2, png::BitDepth::Eight, &[0; 6]));
    let (field, reason) = invalid_reason(read_frame(&path).unwrap_err());
    assert!(field.ends_with("gray8.png") && reason.contains("16-bit grayscale"), "{field}: {reason}");
    let (field, _) = invalid_reason(read_frame(&write(&dir, "junk.png", b"not a png")).unwrap_err());
    assert!(field.ends_with("junk.png"), "{field}");
}

#[test]
fn unknown_extensions_and_missing_files_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (field, reason) = invalid_reason(read_frame(&write(&dir, "cloud.las", b"")).unwrap_err());
    assert!(field.ends_with("cloud.las") && reason.contains("unknown extension"), "{field}: {reason}");
    let missing = dir.path().join("missing.pcd");
    let e = read_frame(&missing).unwrap_err().to_string();
    assert!(e.contains("missing.pcd"), "{e}");
}
