//! Importing a [`PlanningScene`] into the catalog: one new scene whose instances are the
//! collision objects' shapes as exact primitives, at their composed poses, and whose meshes are
//! planned for compound fits.
//!
//! ```text
//! box, sphere, cylinder   the primitive of the same dimensions
//! cone                    the cylinder of its height and base radius (it contains the cone:
//!                         conservative), with a note saying so
//! plane a·x + d = 0       the halfspace {n·u ≤ −d} (n = a/‖a‖): the side opposite the normal is
//!                         solid, as a floor whose normal points up
//! mesh                    with MeshImport::Fit, a planned mesh (ImportPlan::meshes): its
//!                         vertices and triangles in the mesh's own frame and its composed pose,
//!                         for the caller to fit as a compound body (a body containing the mesh)
//!                         and add at that pose; with MeshImport::Skip, skipped with the reason
//! ```
//!
//! A pose composes as MoveIt composes it: the shape's frame maps into the object's header frame
//! by `object pose ∘ shape pose` (`mesh_poses[k]` after `pose`), so a mesh's vertices stay as
//! written and its fitted body's frame is the mesh's frame.
//!
//! Identical primitives (same kind and dimensions, bit for bit) share one stored body within an
//! import. An object with one imported shape names its instance by the object's id; an object
//! with several names each `id#k`, k the shape's index in the object (primitives first, then
//! meshes, then planes, as [`CollisionObject::shapes`] orders them); a planned mesh is named
//! the same way. The allowed-collision matrix and the robot state are returned with the plan,
//! for the caller to keep; the catalog stores the scene, its bodies and its instances
//! ([`Catalog::import_plan`] writes the primitives; the meshes' bodies and instances are added
//! once their fits end, by [`Catalog::add_fitted_body`] and [`Catalog::add_named_instance`]).
//!
//! The plan is made first ([`ImportPlan::new`]), so a caller can check its counts against its
//! limits before anything is written; [`Catalog::import_plan`] then writes it, and removes what it
//! wrote should a write fail.

use super::{CollisionObject, PlanningScene, Shape};
use crate::{Catalog, Error, Result};
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::primitive::{Primitive, PrimitiveFile};

/// One shape of the scene that becomes an instance.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedInstance {
    /// The instance's name: the object's id, with `#k` when the object has several shapes.
    pub name: String,
    /// The collision object's id.
    pub object_id: String,
    /// The shape's index in its object ([`CollisionObject::shapes`]).
    pub shape_index: usize,
    /// The frame the pose is given in (the object's `header.frame_id`; empty when absent).
    pub frame_id: String,
    /// Index of its body in [`ImportPlan::bodies`].
    pub body: usize,
    /// The primitive's kind (`box`, `sphere`, `cylinder`, `halfspace`).
    pub kind: &'static str,
    /// Shape frame → the object's header frame (the object's pose composed with the shape's).
    pub pose: Isometry3,
    /// How the shape was approximated, when it was (a cone by its cylinder); empty otherwise.
    pub note: String,
}

/// What an import does with the scene's meshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshImport {
    /// Each mesh is planned for a compound fit ([`ImportPlan::meshes`]).
    Fit,
    /// Each mesh is skipped with the reason ([`ImportPlan::skipped`]).
    Skip,
}

/// One mesh of the scene planned for a compound fit: the caller fits its triangles, stores the
/// body with the mesh in the mesh's frame, and adds an instance at `pose` named `name`.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedMesh {
    /// The instance's name: the object's id, with `#k` when the object has several shapes.
    pub name: String,
    /// The collision object's id.
    pub object_id: String,
    /// The shape's index in its object ([`CollisionObject::shapes`]).
    pub shape_index: usize,
    /// The frame the pose is given in (the object's `header.frame_id`; empty when absent).
    pub frame_id: String,
    /// Mesh frame → the object's header frame (the object's pose composed with the mesh's).
    pub pose: Isometry3,
    /// Vertices, meters, in the mesh's own frame (as written in the message).
    pub vertices: Vec<[Real; 3]>,
    /// Triangles as indices into `vertices` (validated: in range).
    pub triangles: Vec<[u32; 3]>,
}

/// One shape of the scene that is not imported.
#[derive(Clone, Debug, PartialEq)]
pub struct SkippedShape {
    /// The collision object's id.
    pub object_id: String,
    /// The shape's index in its object.
    pub shape_index: usize,
    /// The shape's kind (`mesh`).
    pub kind: &'static str,
    /// Its pose in the object's header frame, for the caller to add a fitted body there.
    pub pose: Isometry3,
    /// Why it was skipped.
    pub reason: String,
}

/// A planning scene as instances of primitive bodies, not yet written (module docs).
#[derive(Clone, Debug)]
pub struct ImportPlan {
    /// The scene's name in the message (empty when absent).
    pub scene_name: String,
    /// The distinct primitives to store, each with its body name (kind and dimensions).
    pub bodies: Vec<(String, Primitive)>,
    /// The instances, object by object, shape by shape.
    pub instances: Vec<PlannedInstance>,
    /// The meshes to fit (with [`MeshImport::Fit`]; empty with [`MeshImport::Skip`]).
    pub meshes: Vec<PlannedMesh>,
    /// The shapes not imported (the meshes, with [`MeshImport::Skip`]).
    pub skipped: Vec<SkippedShape>,
    /// The planning scene's allowed-collision matrix, kept with the imported scene.
    pub allowed_collision: Option<super::AllowedCollisionMatrix>,
    /// The planning scene's robot state (joint positions by name), kept with the imported scene.
    pub joint_positions: Vec<(String, Real)>,
}

impl ImportPlan {
    /// The plan of `scene` (module docs); `meshes` says whether its meshes are planned for
    /// fits or skipped.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the shape (`world.collision_objects[id].shapes[k]`) whose
    /// dimensions a primitive refuses (the parser's checks admit what a primitive does, so this is
    /// a broken invariant rather than a user's error).
    pub fn new(scene: &PlanningScene, meshes: MeshImport) -> Result<Self> {
        let mut plan = ImportPlan {
            scene_name: scene.name.clone(),
            bodies: Vec::new(),
            instances: Vec::new(),
            meshes: Vec::new(),
            skipped: Vec::new(),
            allowed_collision: scene.allowed_collision.clone(),
            joint_positions: scene.joint_positions.clone(),
        };
        // Dedupe by the primitive file's exact JSON (kind and dimensions, bit for bit).
        let mut seen: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
        for object in &scene.objects {
            plan.add_object(object, meshes, &mut seen)?;
        }
        Ok(plan)
    }

    fn add_object(
        &mut self,
        object: &CollisionObject,
        meshes: MeshImport,
        seen: &mut std::collections::HashMap<String, usize>,
    ) -> Result<()> {
        let name = |k: usize| super::instance_name(&object.id, object.shapes.len(), k);
        for (k, placed) in object.shapes.iter().enumerate() {
            let (file, note) = match &placed.shape {
                Shape::Box { size } => (PrimitiveFile::Box { size: *size }, String::new()),
                Shape::Sphere { radius } => (PrimitiveFile::Sphere { radius: *radius }, String::new()),
                Shape::Cylinder { height, radius } => {
                    (PrimitiveFile::Cylinder { radius: *radius, height: *height }, String::new())
                }
                Shape::Cone { height, radius } => (
                    PrimitiveFile::Cylinder { radius: *radius, height: *height },
                    "a cone, imported as the cylinder of its height and base radius (which contains it)".to_owned(),
                ),
                Shape::Plane { normal, offset } => {
                    (PrimitiveFile::Halfspace { normal: *normal, offset: -*offset }, String::new())
                }
                Shape::Mesh { vertices, triangles } if meshes == MeshImport::Fit => {
                    self.meshes.push(PlannedMesh {
                        name: name(k),
                        object_id: object.id.clone(),
                        shape_index: k,
                        frame_id: object.frame_id.clone(),
                        pose: placed.pose,
                        vertices: vertices.clone(),
                        triangles: triangles.clone(),
                    });
                    continue;
                }
                Shape::Mesh { vertices, triangles } => {
                    self.skipped.push(SkippedShape {
                        object_id: object.id.clone(),
                        shape_index: k,
                        kind: "mesh",
                        pose: placed.pose,
                        reason: format!(
                            "a mesh of {} vertices and {} triangles, not imported: fit it with StartFitJob (`parts` for a compound body) and add the body at this pose",
                            vertices.len(),
                            triangles.len()
                        ),
                    });
                    continue;
                }
            };
            let field = || format!("world.collision_objects[{}].shapes[{k}]", sublevel_core::error::clip(&object.id));
            let primitive = Primitive::from_file(&file).map_err(|e| crate::Error::invalid(field(), e.to_string()))?;
            let key = serde_json::to_string(&file).map_err(|e| Error::invalid(field(), e.to_string()))?;
            let body = *seen.entry(key).or_insert_with(|| {
                self.bodies.push((body_name(&file), primitive));
                self.bodies.len() - 1
            });
            self.instances.push(PlannedInstance {
                name: name(k),
                object_id: object.id.clone(),
                shape_index: k,
                frame_id: object.frame_id.clone(),
                body,
                kind: primitive.kind(),
                pose: placed.pose,
                note,
            });
        }
        Ok(())
    }
}

/// A body's name from its primitive: kind and dimensions, e.g. `box 1.2x1x0.04`,
/// `cylinder r0.05 h0.3`, `halfspace n(0,0,1) d-0.5`. Each number is written in at most 24
/// characters (in exponent form when its decimal form is longer, e.g. a normal's `1e-300`), so
/// the name always fits [`crate::MAX_NAME_BYTES`].
fn body_name(file: &PrimitiveFile) -> String {
    let v = |x: Real| {
        let plain = format!("{x}");
        if plain.len() <= 24 {
            plain
        } else {
            format!("{x:e}")
        }
    };
    match file {
        PrimitiveFile::Box { size } => format!("box {}x{}x{}", v(size[0]), v(size[1]), v(size[2])),
        PrimitiveFile::Sphere { radius } => format!("sphere r{}", v(*radius)),
        PrimitiveFile::Cylinder { radius, height } => format!("cylinder r{} h{}", v(*radius), v(*height)),
        PrimitiveFile::Capsule { radius, height } => format!("capsule r{} h{}", v(*radius), v(*height)),
        PrimitiveFile::Halfspace { normal, offset } => {
            format!("halfspace n({},{},{}) d{}", v(normal[0]), v(normal[1]), v(normal[2]), v(*offset))
        }
    }
}

/// An imported shape: its planned instance with the ids it was stored under.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportedInstance {
    /// What was planned (name, object, kind, pose, note).
    pub planned: PlannedInstance,
    /// The new instance's id.
    pub instance_id: String,
    /// The id of its (shared) primitive body.
    pub body_id: String,
}

/// What [`Catalog::import_plan`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportedScene {
    /// The new scene's id.
    pub scene_id: String,
    /// Its name.
    pub name: String,
    /// The instances, in the plan's order.
    pub instances: Vec<ImportedInstance>,
    /// The ids of the primitive bodies stored, in the plan's order of [`ImportPlan::bodies`].
    pub body_ids: Vec<String>,
}

impl Catalog {
    /// Writes an import plan: a new scene named `name` (the plan's scene name when empty, else
    /// `imported`), one primitive body per distinct primitive, and the instances (in one store
    /// transaction). Should a write fail, what was written is removed again (best effort) and the
    /// error returned.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `name` for an over-long name, or `instances[k].name` /
    /// `meshes[k].name` for an instance name longer than [`crate::MAX_NAME_BYTES`] or used twice
    /// (a plan of [`ImportPlan::new`] has none); [`Error::Storage`].
    pub fn import_plan(&self, name: &str, plan: &ImportPlan) -> Result<ImportedScene> {
        let mut names = std::collections::HashSet::new();
        let planned = plan.instances.iter().map(|p| ("instances", &p.name));
        let meshes = plan.meshes.iter().map(|m| ("meshes", &m.name));
        for (k, (list, n)) in planned.chain(meshes).enumerate() {
            let k = if list == "instances" { k } else { k - plan.instances.len() };
            let field = format!("{list}[{k}].name");
            crate::catalog::check_name(&field, n)?;
            if !names.insert(n.as_str()) {
                let shown = sublevel_core::error::clip(n);
                return Err(Error::invalid(field, format!("instance name `{shown}` is used twice")));
            }
        }
        let name = if !name.is_empty() {
            name
        } else if !plan.scene_name.is_empty() {
            plan.scene_name.as_str()
        } else {
            "imported"
        };
        let scene_id = self.create_scene(name)?;
        let mut body_ids = Vec::with_capacity(plan.bodies.len());
        let written = (|| {
            for (body_name, primitive) in &plan.bodies {
                body_ids.push(self.add_primitive(body_name, *primitive)?);
            }
            let rows: Vec<(&str, Isometry3)> =
                plan.instances.iter().map(|p| (body_ids[p.body].as_str(), p.pose)).collect();
            let ids = self.add_instances(&scene_id, &rows)?;
            let planning = crate::PlanningContext {
                names: ids.iter().zip(&plan.instances).map(|(id, p)| (id.clone(), p.name.clone())).collect(),
                allowed_collision: plan.allowed_collision.clone(),
                joint_positions: plan.joint_positions.clone(),
                robot: None,
            };
            self.set_planning(&scene_id, planning)?;
            Ok(ids)
        })();
        let instance_ids = match written {
            Ok(ids) => ids,
            Err(e) => {
                let _ = self.delete_scene(&scene_id);
                for id in &body_ids {
                    let _ = self.delete_body(id);
                }
                return Err(e);
            }
        };
        let instances = plan
            .instances
            .iter()
            .zip(instance_ids)
            .map(|(p, instance_id)| ImportedInstance {
                planned: p.clone(),
                instance_id,
                body_id: body_ids[p.body].clone(),
            })
            .collect();
        Ok(ImportedScene { scene_id, name: name.to_owned(), instances, body_ids })
    }
}

#[cfg(all(test, feature = "store"))]
mod tests {
    use super::*;
    use crate::store::RedbStore;
    use sublevel_query::shape::{shape_distance, ShapeRef};
    use sublevel_query::NewtonParams;

    /// The ROS-spelled test scene: the table's four shapes named `table#k` (a box, a sphere, the
    /// plane as the halfspace z ≤ 0.5, the APPENDed cylinder), the wedge's mesh skipped with its
    /// pose; identical boxes of two objects share one body.
    #[test]
    fn a_plan_names_its_instances_and_skips_meshes() {
        let scene = PlanningScene::from_yaml(super::super::tests::ROS_SCENE.as_bytes()).unwrap();
        let plan = ImportPlan::new(&scene, MeshImport::Skip).unwrap();
        let names: Vec<&str> = plan.instances.iter().map(|i| i.name.as_str()).collect();
        assert_eq!(names, ["table#0", "table#1", "table#2", "table#3"]);
        let kinds: Vec<&str> = plan.instances.iter().map(|i| i.kind).collect();
        assert_eq!(kinds, ["box", "sphere", "halfspace", "cylinder"]);
        assert_eq!(plan.bodies.len(), 4);
        assert_eq!(plan.bodies[0].0, "box 1.2x1x0.04");
        // The plane z − 0.5 = 0: solid below, {z ≤ 0.5} in its own frame.
        let floor = plan.bodies[plan.instances[2].body].1;
        assert_eq!(floor.to_file(), PrimitiveFile::Halfspace { normal: [0.0, 0.0, 1.0], offset: 0.5 });
        assert_eq!(plan.instances[0].frame_id, "world");
        assert_eq!(plan.skipped.len(), 1);
        assert_eq!((plan.skipped[0].object_id.as_str(), plan.skipped[0].kind), ("wedge", "mesh"));
        assert_eq!(plan.skipped[0].pose.translation.vector.z, 2.0);
        let twins = "world:\n  collision_objects:\n    - id: a\n      primitives: [{type: box, dimensions: [1, 2, 3]}]\n      primitive_poses: [{position: [0, 0, 0]}]\n    - id: b\n      primitives: [{type: box, dimensions: [1, 2, 3]}, {type: cone, dimensions: [1, 0.5]}]\n      primitive_poses: [{position: [5, 0, 0]}, {position: [9, 0, 0]}]\n";
        let plan = ImportPlan::new(&PlanningScene::from_yaml(twins.as_bytes()).unwrap(), MeshImport::Fit).unwrap();
        assert_eq!(plan.bodies.len(), 2, "the two boxes share a body; the cone is a cylinder");
        assert_eq!((plan.instances[0].body, plan.instances[1].body), (0, 0));
        assert_eq!((plan.instances[0].name.as_str(), plan.instances[1].name.as_str()), ("a", "b#0"));
        assert!(plan.instances[2].note.contains("cone"), "{:?}", plan.instances[2].note);
    }

    /// A closed box mesh (8 vertices, 12 triangles) under an object pose and a mesh pose
    /// (`tests/data/box_mesh.scene.yaml`): planned for a fit with the vertices as written and
    /// the composed pose of a hand computation, named by the object's id; the ball stays a
    /// primitive. With [`MeshImport::Skip`] the mesh is skipped at the same pose.
    #[test]
    fn a_mesh_is_planned_at_its_composed_pose_or_skipped() {
        let yaml = include_str!("../../../../tests/data/box_mesh.scene.yaml");
        let scene = PlanningScene::from_yaml(yaml.as_bytes()).unwrap();
        let plan = ImportPlan::new(&scene, MeshImport::Fit).unwrap();
        assert!(plan.skipped.is_empty());
        assert_eq!(plan.instances.iter().map(|i| i.name.as_str()).collect::<Vec<_>>(), ["ball"]);
        assert_eq!(plan.meshes.len(), 1);
        let mesh = &plan.meshes[0];
        assert_eq!((mesh.name.as_str(), mesh.object_id.as_str(), mesh.shape_index), ("crate", "crate", 0));
        assert_eq!(mesh.frame_id, "world");
        assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (8, 12));
        assert_eq!(mesh.vertices[6], [0.1, 0.05, 0.3]);
        // Object: t_o = (1, 2, 0.5), R_o = 90° about z; mesh: t_m = (0.1, 0, 0.2), R_m = 90° about
        // x. t = t_o + R_o t_m = (1, 2, 0.5) + (0, 0.1, 0.2) = (1, 2.1, 0.7); q = q_o ⊗ q_m =
        // (√½, 0, 0, √½) ⊗ (√½, √½, 0, 0) = (½, ½, ½, ½): x → y, y → z, z → x.
        let (q, t) = sublevel_core::math::pose_to_parts(&mesh.pose);
        for (got, want) in t.iter().zip([1.0, 2.1, 0.7]) {
            assert!((got - want).abs() < 1e-15, "{t:?}");
        }
        for got in q {
            assert!((got - 0.5).abs() < 1e-15, "{q:?}");
        }
        // The vertex (0.1, 0.05, 0.3) lands at (1 + 0.3, 2.1 + 0.1, 0.7 + 0.05).
        let corner = mesh.pose * sublevel_core::math::Point3::new(0.1, 0.05, 0.3);
        assert!((corner.coords - sublevel_core::math::Vector3::new(1.3, 2.2, 0.75)).norm() < 1e-15, "{corner:?}");

        let skipped = ImportPlan::new(&scene, MeshImport::Skip).unwrap();
        assert!(skipped.meshes.is_empty());
        assert_eq!(skipped.skipped.len(), 1);
        let s = &skipped.skipped[0];
        assert_eq!((s.object_id.as_str(), s.shape_index, s.kind), ("crate", 0, "mesh"));
        assert_eq!(s.pose, mesh.pose);
        assert!(s.reason.contains("8 vertices and 12 triangles"), "{}", s.reason);
    }

    /// The test scene written to a catalog: its instances at their composed poses answer as
    /// `shape_distance` answers the parsed shapes (the sphere 0.4 m above the plane, the box
    /// against the sphere), and a failed write leaves nothing behind.
    #[test]
    fn an_imported_scene_answers_as_its_parsed_shapes() {
        let dir = tempfile::tempdir().unwrap();
        let catalog =
            Catalog::open(Box::new(RedbStore::open_dir(dir.path()).unwrap()), NewtonParams::default()).unwrap();
        let scene = PlanningScene::from_yaml(super::super::tests::ROS_SCENE.as_bytes()).unwrap();
        let plan = ImportPlan::new(&scene, MeshImport::Skip).unwrap();
        let imported = catalog.import_plan("", &plan).unwrap();
        assert_eq!(imported.name, "kitchen");
        assert_eq!(catalog.get_scene(&imported.scene_id).unwrap().instances.len(), 4);
        assert_eq!(catalog.bodies().len(), 4);
        let id = |k: usize| imported.instances[k].instance_id.as_str();
        let sid = &imported.scene_id;
        // The sphere (table#1) 0.4 m above the plane z = 0.5 (table#2).
        let d = catalog.distance(sid, id(2), id(1)).unwrap();
        assert!((d.distance - 0.4).abs() < 1e-12, "{}", d.distance);
        let table = &scene.objects[0];
        let box_ = Primitive::from_file(&PrimitiveFile::Box { size: [1.2, 1.0, 0.04] }).unwrap();
        let ball = Primitive::from_file(&PrimitiveFile::Sphere { radius: 0.1 }).unwrap();
        let want = shape_distance(
            ShapeRef::Primitive(&box_),
            &table.shapes[0].pose,
            ShapeRef::Primitive(&ball),
            &table.shapes[1].pose,
            None,
        )
        .unwrap();
        let got = catalog.distance(sid, id(0), id(1)).unwrap();
        assert!((got.distance - want.distance).abs() < 1e-12, "{} vs {}", got.distance, want.distance);
        // A name too long for a scene: refused before anything is written.
        let long = "n".repeat(crate::MAX_NAME_BYTES + 1);
        assert!(catalog.import_plan(&long, &plan).is_err());
        assert_eq!((catalog.scenes().len(), catalog.bodies().len()), (1, 4));
    }
}
