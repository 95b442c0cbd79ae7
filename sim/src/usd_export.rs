//! `kitchen-r sim export --usd`: a scene as USD ASCII (`.usda`) so Isaac Sim users can open our
//! kitchens. Hand-written text, no USD dependency; the same scene always gives the same bytes.
//!
//! What is written: a root `Xform` named after the scene with one `Xform` per body (the room,
//! each furniture item, each zone, each key object at its start, the robot base at the middle of
//! the first start segment), each posed by `xformOp:translate` + `xformOp:orient` in the world
//! frame (z up, metres). Under each body its geometry as `Cube` (size 2 scaled by the half
//! extents), `Cylinder` or `Sphere` prims with `primvars:displayColor`: exactly the boxes,
//! cylinders and balls the twin collides with and renders (`furniture::parts`,
//! `world::object_shapes`). Colliding prims carry `PhysicsCollisionAPI`, key objects
//! `PhysicsRigidBodyAPI` and their mass; decorations do not collide; zones are `guide` prims (the
//! robot's cameras never see them). What geometry cannot say (furniture kind and outer box, zone
//! colours, approach points and names, start segments) travels as `kitchenr:` custom attributes,
//! which the reader (`kitchen_r_core::usd_scene`) turns back into a scene.

use std::fmt::Write as _;

use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::scene::Scene;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::SharedShape;

use crate::convert::planar;
use crate::episode::object_color;
use crate::error::SimError;
use crate::furniture;
use crate::robot::desc::RobotDesc;
use crate::world::{floor_box, object_shapes, wall_boxes};

/// Applied schemas of a prim that collides in PhysX.
const COLLIDES: &[&str] = &["PhysicsCollisionAPI"];
/// Thickness of a zone's marker plate (m): visible as a sheet, never an obstacle.
const ZONE_MARKER: f64 = 0.002;

/// USD text being written, with the indentation of the open prim.
struct Usda {
    out: String,
    depth: usize,
}

impl Usda {
    fn line(&mut self, text: &str) {
        let _ = writeln!(self.out, "{:indent$}{text}", "", indent = self.depth * 4);
    }

    /// `def Type "name" (prepend apiSchemas = [...])` and its opening brace.
    fn open(&mut self, kind: &str, name: &str, schemas: &[&str]) {
        if schemas.is_empty() {
            self.line(&format!("def {kind} \"{}\"", prim_name(name)));
        } else {
            let list: Vec<String> = schemas.iter().map(|s| format!("\"{s}\"")).collect();
            self.line(&format!("def {kind} \"{}\" (", prim_name(name)));
            self.line(&format!("    prepend apiSchemas = [{}]", list.join(", ")));
            self.line(")");
        }
        self.line("{");
        self.depth += 1;
    }

    fn close(&mut self) {
        self.depth -= 1;
        self.line("}");
    }

    fn string(&mut self, name: &str, value: &str) {
        self.line(&format!("custom string kitchenr:{name} = {}", quote(value)));
    }

    /// `xformOp:translate` and `xformOp:orient` (and `xformOp:scale` when given), in that order.
    fn pose(&mut self, pose: &Isometry3<f64>, scale: Option<[f64; 3]>) {
        let t = pose.translation.vector;
        let q = pose.rotation;
        self.line(&format!(
            "double3 xformOp:translate = {}",
            tuple(&[t.x, t.y, t.z])
        ));
        self.line(&format!(
            "quatd xformOp:orient = {}",
            tuple(&[q.w, q.i, q.j, q.k])
        ));
        let mut order = vec!["\"xformOp:translate\"", "\"xformOp:orient\""];
        if let Some(s) = scale {
            self.line(&format!("double3 xformOp:scale = {}", tuple(&s)));
            order.push("\"xformOp:scale\"");
        }
        self.line(&format!("uniform token[] xformOpOrder = [{}]", order.join(", ")));
    }

    fn color(&mut self, c: [f32; 3]) {
        self.line(&format!("color3f[] primvars:displayColor = [{}]", color(c)));
    }

    /// A box of half extents `half` at `pose` (parent frame).
    fn cube(&mut self, name: &str, pose: &Isometry3<f64>, half: [f64; 3], c: [f32; 3], collides: bool) {
        self.open("Cube", name, if collides { COLLIDES } else { &[] });
        self.line("double size = 2");
        self.pose(pose, Some(half));
        self.color(c);
        self.close();
    }

    /// One collider shape of an object (f32 as the physics holds it).
    fn shape(&mut self, name: &str, pose: &Isometry3<f64>, shape: &SharedShape, c: [f32; 3]) {
        if let Some(b) = shape.as_cuboid() {
            let h = b.half_extents;
            let half = [h.x, h.y, h.z].map(f64::from);
            return self.cube(name, pose, half, c, true);
        }
        if let Some(b) = shape.as_ball() {
            self.open("Sphere", name, COLLIDES);
            self.line(&format!("double radius = {}", b.radius));
        } else if let Some(cy) = shape.as_cylinder() {
            // parry's cylinders stand along their local y.
            self.open("Cylinder", name, COLLIDES);
            self.line("uniform token axis = \"Y\"");
            self.line(&format!("double height = {}", 2.0 * cy.half_height));
            self.line(&format!("double radius = {}", cy.radius));
        } else if let Some(hull) = shape.as_convex_polyhedron() {
            // A mesh object's convex hull, as it collides and renders.
            let (points, triangles) = hull.to_trimesh();
            self.open("Mesh", name, COLLIDES);
            let p: Vec<String> = points
                .iter()
                .map(|v| format!("({}, {}, {})", v.x, v.y, v.z))
                .collect();
            self.line(&format!("point3f[] points = [{}]", p.join(", ")));
            self.line(&format!(
                "int[] faceVertexCounts = [{}]",
                vec!["3"; triangles.len()].join(", ")
            ));
            let idx: Vec<String> = triangles.iter().flatten().map(u32::to_string).collect();
            self.line(&format!("int[] faceVertexIndices = [{}]", idx.join(", ")));
        } else {
            // object_shapes makes only the kinds above; a new kind must be taught here.
            self.open("Xform", name, &[]);
        }
        self.pose(pose, None);
        self.color(c);
        self.close();
    }
}

/// The scene as `.usda` text, the robot base standing at the middle of the first start segment.
pub fn scene_usda(scene: &Scene, catalogue: &Catalogue, robot: &RobotDesc) -> Result<String, SimError> {
    let mut u = Usda {
        out: String::new(),
        depth: 0,
    };
    u.line("#usda 1.0");
    u.line("(");
    u.line(&format!("    defaultPrim = \"{}\"", prim_name(&scene.id)));
    u.line(&format!(
        "    doc = {}",
        quote(&format!(
            "Kitchen-R scene {}: kitchen-r sim export --usd",
            scene.id
        ))
    ));
    u.line("    metersPerUnit = 1");
    u.line("    upAxis = \"Z\"");
    u.line(")");
    u.line("");
    u.open("Xform", &scene.id, &[]);
    u.string("id", &scene.id);
    u.string("name", &scene.name);
    u.string("description", &scene.description);
    let segments: Vec<f64> = scene
        .start_segments
        .iter()
        .flat_map(|s| [s.from[0], s.from[1], s.to[0], s.to[1], s.heading])
        .collect();
    u.line(&format!(
        "custom double[] kitchenr:startSegments = {}",
        list(&segments)
    ));
    let areas: Vec<f64> = scene
        .background_areas
        .iter()
        .flat_map(|a| [a.center[0], a.center[1], a.size[0], a.size[1], a.height])
        .collect();
    u.line(&format!(
        "custom double[] kitchenr:backgroundAreas = {}",
        list(&areas)
    ));
    room(&mut u, scene);
    u.open("Xform", "Furniture", &[]);
    for f in &scene.furniture {
        u.open("Xform", &f.id, &[]);
        u.string("id", &f.id);
        u.string("kind", kind_name(f));
        u.line(&format!("custom double3 kitchenr:size = {}", tuple(&f.size)));
        u.line(&format!("custom double kitchenr:scale = {}", f.scale));
        u.line(&format!("custom color3f kitchenr:color = {}", color(f.color)));
        u.line(&format!("custom double[] kitchenr:levels = {}", list(&f.levels)));
        u.pose(&planar(f.pose[0], f.pose[1], 0.0, f.pose[2]), None);
        if let Some(m) = &f.mesh
            && let Some(mesh) = crate::mesh::cached(&m.file, m.scale)
        {
            // The item's own mesh, standing on the floor as the twin places it.
            u.open("Mesh", "mesh", COLLIDES);
            let p: Vec<String> = mesh.vertices.iter().map(|v| tuple(v)).collect();
            u.line(&format!("point3f[] points = [{}]", p.join(", ")));
            u.line(&format!(
                "int[] faceVertexCounts = [{}]",
                vec!["3"; mesh.triangles.len()].join(", ")
            ));
            let idx: Vec<String> = mesh.triangles.iter().flatten().map(u32::to_string).collect();
            u.line(&format!("int[] faceVertexIndices = [{}]", idx.join(", ")));
            u.pose(&planar(0.0, 0.0, mesh.size[2] / 2.0, 0.0), None);
            u.color(f.color);
            u.close();
        }
        for (i, p) in furniture::parts(scene, f).iter().enumerate() {
            let pose = Isometry3::from_parts(
                Translation3::from(Vector3::from(p.center)),
                UnitQuaternion::identity(),
            );
            u.cube(&format!("part_{i}"), &pose, p.half, p.color, !p.decoration);
        }
        u.close();
    }
    u.close();
    zones(&mut u, scene);
    objects(&mut u, scene, catalogue)?;
    robot_base(&mut u, scene, robot);
    u.close();
    Ok(u.out)
}

fn room(u: &mut Usda, scene: &Scene) {
    let r = &scene.room;
    u.open("Xform", "Room", &[]);
    u.line(&format!("custom double2 kitchenr:size = {}", tuple(&r.size)));
    u.line(&format!("custom double kitchenr:wallHeight = {}", r.wall_height));
    u.line(&format!(
        "custom double kitchenr:wallThickness = {}",
        r.wall_thickness
    ));
    u.line(&format!(
        "custom color3f kitchenr:floorColor = {}",
        color(r.floor_color)
    ));
    u.line(&format!(
        "custom color3f kitchenr:wallColor = {}",
        color(r.wall_color)
    ));
    u.pose(&Isometry3::identity(), None);
    let (pose, half) = floor_box(scene);
    u.cube("Floor", &pose, half, r.floor_color, true);
    for ((pose, half), name) in
        wall_boxes(scene)
            .iter()
            .zip(["WallSouth", "WallNorth", "WallWest", "WallEast"])
    {
        u.cube(name, pose, *half, r.wall_color, true);
    }
    u.close();
}

/// Zones as guide plates on their surfaces; the approach pose and names as attributes.
fn zones(u: &mut Usda, scene: &Scene) {
    u.open("Xform", "Zones", &[]);
    for z in &scene.zones {
        u.open("Xform", &z.color, &[]);
        u.string("color", &z.color);
        u.string("furniture", &z.furniture);
        u.line(&format!(
            "custom double3 kitchenr:approach = {}",
            tuple(&z.approach)
        ));
        let names: Vec<String> = z.names.iter().map(|n| quote(n)).collect();
        u.line(&format!(
            "custom string[] kitchenr:names = [{}]",
            names.join(", ")
        ));
        u.pose(&planar(z.center[0], z.center[1], z.height, 0.0), None);
        let plate = planar(0.0, 0.0, ZONE_MARKER / 2.0, 0.0);
        u.open("Cube", "area", &[]);
        u.line("uniform token purpose = \"guide\"");
        u.line("double size = 2");
        u.pose(
            &plate,
            Some([z.size[0] / 2.0, z.size[1] / 2.0, ZONE_MARKER / 2.0]),
        );
        u.color(z.rgb);
        u.close();
        u.close();
    }
    u.close();
}

/// Key objects at their starts, each a rigid body of the catalogue's mass.
fn objects(u: &mut Usda, scene: &Scene, catalogue: &Catalogue) -> Result<(), SimError> {
    u.open("Xform", "Objects", &[]);
    for o in &scene.key_objects {
        let model = catalogue
            .model(&o.model)
            .ok_or_else(|| SimError::UnknownObject(o.model.clone()))?;
        let start = scene
            .key_object_start(o, model.shape.half_height())
            .ok_or_else(|| SimError::Episode(format!("{}: unknown zone {:?}", o.name(), o.zone)))?;
        u.open("Xform", &o.name(), &["PhysicsRigidBodyAPI", "PhysicsMassAPI"]);
        u.string("model", &o.model);
        if let Some(v) = &o.variant {
            u.string("variant", v);
        }
        u.string("zone", &o.zone);
        u.line(&format!("float physics:mass = {}", model.mass as f32));
        u.pose(&planar(start[0], start[1], start[2], o.yaw), None);
        let c = object_color(model, o.variant.as_deref());
        for (i, (pose, shape)) in object_shapes(&model.shape).iter().enumerate() {
            u.shape(&format!("shape_{i}"), pose, shape, c);
        }
        u.close();
    }
    u.close();
    Ok(())
}

/// The base as a cylinder and the arm's column as a box, at the middle of the first start segment.
fn robot_base(u: &mut Usda, scene: &Scene, robot: &RobotDesc) {
    let b = &robot.base;
    let Some(s) = scene.start_segments.first() else {
        return;
    };
    let mid = [(s.from[0] + s.to[0]) / 2.0, (s.from[1] + s.to[1]) / 2.0];
    u.open("Xform", "Robot", &[]);
    u.pose(&planar(mid[0], mid[1], 0.0, s.heading), None);
    u.open("Cylinder", "base", COLLIDES);
    u.line("uniform token axis = \"Z\"");
    u.line(&format!("double height = {}", b.height - b.clearance));
    u.line(&format!("double radius = {}", b.body_radius));
    u.pose(&planar(0.0, 0.0, (b.height + b.clearance) / 2.0, 0.0), None);
    u.color(b.color);
    u.close();
    let c = b.column_center;
    u.cube(
        "column",
        &planar(c[0], c[1], c[2], 0.0),
        b.column_size.map(|v| v / 2.0),
        b.color,
        true,
    );
    u.close();
}

fn kind_name(f: &kitchen_r_core::scene::Furniture) -> &'static str {
    use kitchen_r_core::scene::FurnitureKind as K;
    match f.kind {
        K::Counter => "counter",
        K::Table => "table",
        K::Shelf => "shelf",
        K::Sink => "sink",
        K::Stove => "stove",
        K::Fridge => "fridge",
        K::Cabinet => "cabinet",
    }
}

/// A valid USD prim name: letters, digits and `_`, not starting with a digit. Ids such as
/// `red cup` become `red_cup`; the exact id stays in `kitchenr:` attributes.
pub fn prim_name(id: &str) -> String {
    let mut s: String = id
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    s
}

/// A USD string literal.
fn quote(s: &str) -> String {
    let mut q = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            '\n' => q.push_str("\\n"),
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

/// `(a, b, c)`; Rust's shortest round-trip float formatting keeps every value exact.
fn tuple(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
    format!("({})", items.join(", "))
}

fn list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
    format!("[{}]", items.join(", "))
}

fn color(c: [f32; 3]) -> String {
    format!("({}, {}, {})", c[0], c[1], c[2])
}

/// Write scene `scene_id` of the default assets to `out` as `.usda`.
pub fn export_scene(scene_id: &str, out: &std::path::Path) -> Result<(), SimError> {
    let assets = crate::sim::Assets::load_default()?;
    let text = scene_usda(assets.scene(scene_id)?, &assets.catalogue, &assets.robot)?;
    std::fs::write(out, text).map_err(|source| SimError::Io {
        path: out.to_path_buf(),
        source,
    })
}
