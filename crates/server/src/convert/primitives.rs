//! Exact primitives: the `Primitive` message ↔ [`sublevel_core::primitive::Primitive`], with the
//! checks of [`Primitive::from_file`] and errors naming the field (`primitive.size[1]`).

use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::Real;
use sublevel_core::primitive::{Primitive, PrimitiveFile};

/// Validates a `Primitive` message: its kind, the fields of that kind (a box's three sizes, a
/// radius, a height, a halfspace's normal and offset) and no field of another kind.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `{field}.kind` (unspecified or undefined),
/// `{field}.size` (not 3 entries for a box), `{field}.size[i]`, `{field}.radius`,
/// `{field}.height`, `{field}.normal`, `{field}.offset` (a bad value, or a field the kind has
/// not).
pub fn primitive_from_proto(p: &pb::Primitive, field: &str) -> Result<Primitive> {
    let kind = pb::PrimitiveKind::try_from(p.kind)
        .map_err(|_| Error::invalid(format!("{field}.kind"), format!("undefined value {}", p.kind)))?;
    let name = match kind {
        pb::PrimitiveKind::Unspecified => {
            return Err(Error::invalid(
                format!("{field}.kind"),
                "must name the primitive: BOX, SPHERE, CYLINDER, CAPSULE or HALFSPACE",
            ))
        }
        pb::PrimitiveKind::Box => "box",
        pb::PrimitiveKind::Sphere => "sphere",
        pb::PrimitiveKind::Cylinder => "cylinder",
        pb::PrimitiveKind::Capsule => "capsule",
        pb::PrimitiveKind::Halfspace => "halfspace",
    };
    // Fields of another kind must be unset: a radius sent with a box is a mistake, not a default.
    let set = [
        ("size", !p.size.is_empty(), name == "box"),
        ("radius", p.radius != 0.0, matches!(name, "sphere" | "cylinder" | "capsule")),
        ("height", p.height != 0.0, matches!(name, "cylinder" | "capsule")),
        ("normal", p.normal.is_some(), name == "halfspace"),
        ("offset", p.offset != 0.0, name == "halfspace"),
    ];
    if let Some((f, _, _)) = set.iter().find(|(_, present, allowed)| *present && !allowed) {
        return Err(Error::invalid(format!("{field}.{f}"), format!("a {name} has no `{f}`; leave it unset")));
    }
    let file = match kind {
        pb::PrimitiveKind::Box => {
            let size: [Real; 3] = p.size.as_slice().try_into().map_err(|_| {
                Error::invalid(format!("{field}.size"), format!("a box needs 3 side lengths, got {}", p.size.len()))
            })?;
            PrimitiveFile::Box { size }
        }
        pb::PrimitiveKind::Sphere => PrimitiveFile::Sphere { radius: p.radius },
        pb::PrimitiveKind::Cylinder => PrimitiveFile::Cylinder { radius: p.radius, height: p.height },
        pb::PrimitiveKind::Capsule => PrimitiveFile::Capsule { radius: p.radius, height: p.height },
        _ => {
            let n = p.normal.as_ref().map_or([0.0; 3], |v| [v.x, v.y, v.z]);
            PrimitiveFile::Halfspace { normal: n, offset: p.offset }
        }
    };
    Primitive::from_file(&file).map_err(|e| super::prefix_field(e, field))
}

/// A primitive as the proto message (full lengths, a unit normal).
pub fn primitive_to_proto(p: &Primitive) -> pb::Primitive {
    let mut out = pb::Primitive::default();
    match p.to_file() {
        PrimitiveFile::Box { size } => {
            out.kind = pb::PrimitiveKind::Box as i32;
            out.size = size.to_vec();
        }
        PrimitiveFile::Sphere { radius } => {
            out.kind = pb::PrimitiveKind::Sphere as i32;
            out.radius = radius;
        }
        PrimitiveFile::Cylinder { radius, height } => {
            out.kind = pb::PrimitiveKind::Cylinder as i32;
            (out.radius, out.height) = (radius, height);
        }
        PrimitiveFile::Capsule { radius, height } => {
            out.kind = pb::PrimitiveKind::Capsule as i32;
            (out.radius, out.height) = (radius, height);
        }
        PrimitiveFile::Halfspace { normal, offset } => {
            out.kind = pb::PrimitiveKind::Halfspace as i32;
            out.normal = Some(pb::Vec3 { x: normal[0], y: normal[1], z: normal[2] });
            out.offset = offset;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field_of(p: pb::Primitive) -> String {
        match primitive_from_proto(&p, "primitive") {
            Err(Error::InvalidArgument { field, .. }) => field,
            other => panic!("{other:?}"),
        }
    }

    /// Each primitive survives its round trip; bad fields are named with their path.
    #[test]
    fn primitives_round_trip_and_bad_fields_are_named() {
        let boxed =
            pb::Primitive { kind: pb::PrimitiveKind::Box as i32, size: vec![1.0, 2.0, 3.0], ..Default::default() };
        let cases = [
            boxed.clone(),
            pb::Primitive { kind: pb::PrimitiveKind::Sphere as i32, radius: 0.5, ..Default::default() },
            pb::Primitive { kind: pb::PrimitiveKind::Cylinder as i32, radius: 0.5, height: 2.0, ..Default::default() },
            pb::Primitive { kind: pb::PrimitiveKind::Capsule as i32, radius: 0.5, ..Default::default() },
            pb::Primitive {
                kind: pb::PrimitiveKind::Halfspace as i32,
                normal: Some(pb::Vec3 { x: 0.0, y: 0.0, z: 1.0 }),
                offset: -0.5,
                ..Default::default()
            },
        ];
        for p in cases {
            let back = primitive_to_proto(&primitive_from_proto(&p, "primitive").unwrap());
            assert_eq!(back, p);
        }
        assert_eq!(field_of(pb::Primitive { size: vec![1.0, -2.0, 3.0], ..boxed.clone() }), "primitive.size[1]");
        assert_eq!(field_of(pb::Primitive { size: vec![1.0, 2.0], ..boxed.clone() }), "primitive.size");
        assert_eq!(field_of(pb::Primitive { radius: 1.0, ..boxed.clone() }), "primitive.radius");
        assert_eq!(field_of(pb::Primitive { kind: 0, ..boxed.clone() }), "primitive.kind");
        assert_eq!(field_of(pb::Primitive { kind: 17, ..boxed }), "primitive.kind");
        let sphere = pb::Primitive { kind: pb::PrimitiveKind::Sphere as i32, radius: f64::NAN, ..Default::default() };
        assert_eq!(field_of(sphere), "primitive.radius");
        let plane = pb::Primitive { kind: pb::PrimitiveKind::Halfspace as i32, ..Default::default() };
        assert_eq!(field_of(plane), "primitive.normal");
    }
}
