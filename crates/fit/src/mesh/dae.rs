//! COLLADA (`.dae`), read by openrr's mesh-loader (the mesh reader of the openrr robotics
//! crates): the triangles of every mesh the document's visual scene instances, in meters —
//! mesh-loader applies the document's `<unit meter="…">` to the vertices and the node transforms
//! above each instance. One difference from assimp (which pinocchio and coal use): where a
//! document has both a unit other than meters and node translations, mesh-loader does not scale
//! the translations by the unit; robot meshes are exported with one or the other. The XML is
//! parsed whole (the byte limits of the request bound it); the vertex count is checked against
//! `max_points` after.

use super::limits::{exhausted, guarded, invalid};
use super::TriangleMesh;
use sublevel_core::math::{Point3, Real};
use sublevel_core::Result;

/// The triangle mesh of COLLADA bytes: every instanced mesh, merged (vertices in meters, not
/// welded).
pub(super) fn parse_dae_mesh(bytes: &[u8], max_points: usize) -> Result<TriangleMesh> {
    let scene = guarded("dae", || {
        mesh_loader::collada::from_slice(bytes).map_err(|e| invalid(format!("malformed dae file: {e}")))
    })?;
    let total: usize = scene.meshes.iter().map(|m| m.vertices.len()).sum();
    if total > max_points {
        return Err(exhausted(format!(
            "the dae file has {total} vertices, which exceeds the limit of {max_points} points"
        )));
    }
    let mut mesh = TriangleMesh { vertices: Vec::with_capacity(total), triangles: Vec::new() };
    for m in &scene.meshes {
        let base = mesh.vertices.len() as u32;
        let n = m.vertices.len() as u32;
        if let Some(f) = m.faces.iter().find(|f| f.iter().any(|&i| i >= n)) {
            return Err(invalid(format!("dae mesh `{}`: face {f:?} names a vertex beyond its {n}", m.name)));
        }
        mesh.vertices.extend(m.vertices.iter().map(|v| Point3::new(v[0] as Real, v[1] as Real, v[2] as Real)));
        mesh.triangles.extend(m.faces.iter().map(|f| [f[0] + base, f[1] + base, f[2] + base]));
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::super::{load_triangle_mesh, MeshFormat};

    /// A cube of side 100 (UNIT), its node moved by NODE.
    const CUBE: &str = r##"<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="UNIT"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries>
    <geometry id="cube-mesh" name="cube"><mesh>
      <source id="cube-positions">
        <float_array id="cube-positions-array" count="24">-50 -50 -50 50 -50 -50 50 50 -50 -50 50 -50 -50 -50 50 50 -50 50 50 50 50 -50 50 50</float_array>
        <technique_common><accessor source="#cube-positions-array" count="8" stride="3">
          <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
        </accessor></technique_common>
      </source>
      <vertices id="cube-vertices"><input semantic="POSITION" source="#cube-positions"/></vertices>
      <triangles count="12">
        <input semantic="VERTEX" source="#cube-vertices" offset="0"/>
        <p>0 3 2 0 2 1 4 5 6 4 6 7 0 1 5 0 5 4 1 2 6 1 6 5 2 3 7 2 7 6 3 0 4 3 4 7</p>
      </triangles>
    </mesh></geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="Scene" name="Scene">
      <node id="cube" name="cube"><translate>NODE</translate><instance_geometry url="#cube-mesh"/></node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>"##;

    /// In millimeters with no node translation, and in meters (side 0.1) with the node moved
    /// 0.1 m up, the cube reads as 12 triangles of the cube [−0.05, 0.05]² × [0.05, 0.15] m,
    /// outward-facing: the divergence-theorem volume is 0.001 m³ and every triangle's area
    /// 0.005 m² (f32 coordinates).
    #[test]
    fn a_collada_cube_reads_in_meters_at_its_node() {
        assert_eq!(MeshFormat::of_path(std::path::Path::new("link/base.DAE")).unwrap(), MeshFormat::Dae);
        let millimeters = CUBE.replace("UNIT", "0.001").replace("NODE", "0 0 0").replace(
            "-50 -50 -50 50 -50 -50 50 50 -50 -50 50 -50 -50 -50 50 50 -50 50 50 50 50 -50 50 50",
            "-50 -50 50 50 -50 50 50 50 50 -50 50 50 -50 -50 150 50 -50 150 50 50 150 -50 50 150",
        );
        let meters = CUBE.replace("UNIT", "1").replace("NODE", "0 0 0.1").replace("-50 -50 -50 50 -50 -50 50 50 -50 -50 50 -50 -50 -50 50 50 -50 50 50 50 50 -50 50 50", "-0.05 -0.05 -0.05 0.05 -0.05 -0.05 0.05 0.05 -0.05 -0.05 0.05 -0.05 -0.05 -0.05 0.05 0.05 -0.05 0.05 0.05 0.05 0.05 -0.05 0.05 0.05");
        for text in [millimeters, meters] {
            check_cube(&text);
        }
    }

    fn check_cube(text: &str) {
        let mesh = load_triangle_mesh(text.as_bytes(), MeshFormat::Dae, 1000).unwrap();
        assert_eq!(mesh.triangles.len(), 12);
        for v in &mesh.vertices {
            for (c, (lo, hi)) in v.iter().zip([(-0.05, 0.05), (-0.05, 0.05), (0.05, 0.15)]) {
                assert!((c - lo).abs() < 1e-8 || (c - hi).abs() < 1e-8, "{v}");
            }
        }
        let mut volume = 0.0;
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize].coords);
            assert!(((b - a).cross(&(c - a)).norm() / 2.0 - 0.005).abs() < 1e-9);
            volume += a.dot(&b.cross(&c)) / 6.0;
        }
        assert!((volume - 0.001).abs() < 1e-9, "{volume}");
        // Too many vertices for the limit, and bytes that are not COLLADA.
        assert!(matches!(
            load_triangle_mesh(text.as_bytes(), MeshFormat::Dae, 4),
            Err(sublevel_core::Error::ResourceExhausted(_))
        ));
        let e = load_triangle_mesh(b"<nope", MeshFormat::Dae, 1000).unwrap_err();
        assert!(matches!(e, sublevel_core::Error::InvalidArgument { .. }), "{e:?}");
    }
}
