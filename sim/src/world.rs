//! Scene → rapier world: floor, walls and furniture as one fixed body of boxes, key and
//! background objects as dynamic bodies with the catalogue's mass and friction. Everything comes
//! from the scene file and the catalogue, so a new scene or object model is a data change only.

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, TAU};

use kitchen_r_core::catalogue::{ObjectModel, Shape};
use kitchen_r_core::scene::Scene;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};

use crate::config::LightConfig;
use crate::convert::{iso_to_pose, planar};
use crate::furniture;
use crate::material::{Material, Materials, Owner, Pattern, Tag};

/// Friction of furniture and walls.
const STATIC_FRICTION: f32 = 0.8;

/// The looks of one episode: the scene's colours and patterns and the sensors' light unless
/// randomised ([`mod@crate::randomise`]). The optional fields are absent from configs written before
/// they existed and from unrandomised ones, so those load and render exactly as before.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Style {
    pub floor_color: [f32; 3],
    pub wall_color: [f32; 3],
    /// Floor tile size (m).
    pub floor_tile: f32,
    /// Floor pattern instead of tiles of `floor_tile`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor_pattern: Option<Pattern>,
    /// Wall pattern instead of the default faint bands.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_pattern: Option<Pattern>,
    /// Pattern of the furniture's solid parts (grain, panels) instead of plain.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub furniture_pattern: Option<Pattern>,
    /// Furniture colour by furniture id, replacing the scene's.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub furniture_colors: BTreeMap<String, [f32; 3]>,
    /// The light of this episode instead of `configs/sensors.toml`'s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light: Option<LightConfig>,
}

impl Style {
    pub fn of(scene: &Scene) -> Style {
        Style {
            floor_color: scene.room.floor_color,
            wall_color: scene.room.wall_color,
            floor_tile: 0.3,
            floor_pattern: None,
            wall_pattern: None,
            furniture_pattern: None,
            furniture_colors: BTreeMap::new(),
            light: None,
        }
    }
}

/// Insert a collider for a box of half extents `half` at `pose`, tagged.
fn add_box(
    world: &mut PhysicsWorld,
    body: RigidBodyHandle,
    pose: Isometry3<f64>,
    half: [f64; 3],
    material: u32,
    owner: Owner,
) {
    let h = half.map(|v| v as f32);
    let co = ColliderBuilder::cuboid(h[0], h[1], h[2])
        .position(iso_to_pose(&pose))
        .friction(STATIC_FRICTION)
        .collision_groups(owner.groups(false))
        .user_data(
            Tag {
                material,
                owner,
                index: 0,
            }
            .pack(),
        );
    world.insert_collider(co, Some(body));
}

/// The floor slab under the room and its walls: pose and half extents (shared with the USD
/// export, so both describe the same boxes).
pub fn floor_box(scene: &Scene) -> (Isometry3<f64>, [f64; 3]) {
    let [rx, ry] = scene.room.size;
    let t = scene.room.wall_thickness;
    (
        planar(rx / 2.0, ry / 2.0, -0.05, 0.0),
        [rx / 2.0 + t, ry / 2.0 + t, 0.05],
    )
}

/// The four walls (south, north, west, east): pose and half extents.
pub fn wall_boxes(scene: &Scene) -> [(Isometry3<f64>, [f64; 3]); 4] {
    let [rx, ry] = scene.room.size;
    let (t, wh) = (scene.room.wall_thickness, scene.room.wall_height);
    [
        ([rx / 2.0, -t / 2.0], [rx / 2.0 + t, t / 2.0]),
        ([rx / 2.0, ry + t / 2.0], [rx / 2.0 + t, t / 2.0]),
        ([-t / 2.0, ry / 2.0], [t / 2.0, ry / 2.0 + t]),
        ([rx + t / 2.0, ry / 2.0], [t / 2.0, ry / 2.0 + t]),
    ]
    .map(|(c, h)| (planar(c[0], c[1], wh / 2.0, 0.0), [h[0], h[1], wh / 2.0]))
}

/// Floor, walls and furniture as one fixed body.
pub fn build_static(world: &mut PhysicsWorld, mats: &mut Materials, scene: &Scene, style: &Style) {
    let body = world.insert_body(RigidBodyBuilder::fixed());
    let floor = mats.add(Material {
        color: style.floor_color,
        pattern: style.floor_pattern.unwrap_or(Pattern::Tiles {
            size: style.floor_tile,
            contrast: 0.12,
        }),
    });
    let (floor_pose, floor_half) = floor_box(scene);
    add_box(world, body, floor_pose, floor_half, floor, Owner::Static);
    let wall = mats.add(Material {
        color: style.wall_color,
        pattern: style.wall_pattern.unwrap_or(Pattern::Stripes {
            size: 1.2,
            contrast: 0.06,
        }),
    });
    for (pose, half) in wall_boxes(scene) {
        add_box(world, body, pose, half, wall, Owner::Static);
    }
    for f in &scene.furniture {
        let base = planar(f.pose[0], f.pose[1], 0.0, f.pose[2]);
        let mut f = f.clone();
        if let Some(c) = style.furniture_colors.get(&f.id) {
            f.color = *c;
        }
        for p in furniture::parts(scene, &f) {
            let pose = base * Translation3::from(Vector3::from(p.center));
            let owner = if p.decoration {
                Owner::Decoration
            } else {
                Owner::Static
            };
            let pattern = match style.furniture_pattern {
                Some(pattern) if !p.decoration => pattern,
                _ => Pattern::Plain,
            };
            let material = mats.add(Material {
                color: p.color,
                pattern,
            });
            add_box(world, body, pose, p.half, material, owner);
        }
        if let Some(m) = &f.mesh {
            add_mesh(world, mats, body, base, &f, m, style);
        }
    }
}

/// A mesh furniture item as one static triangle-mesh collider, collided with and ray cast
/// exactly (loaded and size-checked with the assets, so the cache holds it).
fn add_mesh(
    world: &mut PhysicsWorld,
    mats: &mut Materials,
    body: RigidBodyHandle,
    base: Isometry3<f64>,
    f: &kitchen_r_core::scene::Furniture,
    m: &kitchen_r_core::scene::MeshRef,
    style: &Style,
) {
    let Some(mesh) = crate::mesh::cached(&m.file, m.scale) else {
        return;
    };
    let Some(shape) = mesh.trimesh() else { return };
    let material = mats.add(Material {
        color: f.color,
        pattern: style.furniture_pattern.unwrap_or(Pattern::Plain),
    });
    // The mesh is centred on its bounding box; the item stands on the floor.
    let pose = base * Translation3::new(0.0, 0.0, mesh.size[2] / 2.0);
    let co = ColliderBuilder::new(shape)
        .position(iso_to_pose(&pose))
        .friction(STATIC_FRICTION)
        .collision_groups(Owner::Static.groups(false))
        .user_data(
            Tag {
                material,
                owner: Owner::Static,
                index: 0,
            }
            .pack(),
        );
    world.insert_collider(co, Some(body));
}

/// Collision/render pieces of an object model relative to its centre (bounding-box centre).
pub fn object_shapes(shape: &Shape) -> Vec<(Isometry3<f64>, SharedShape)> {
    // parry's cylinders stand along y; ours along z.
    let upright = UnitQuaternion::from_euler_angles(FRAC_PI_2, 0.0, 0.0);
    match *shape {
        Shape::Sphere { radius } => vec![(Isometry3::identity(), SharedShape::ball(radius as f32))],
        Shape::Cylinder { radius, height } => vec![(
            Isometry3::from_parts(Translation3::identity(), upright),
            SharedShape::cylinder((height / 2.0) as f32, radius as f32),
        )],
        Shape::Cuboid { size } => {
            vec![(
                Isometry3::identity(),
                SharedShape::cuboid(size[0] as f32 / 2.0, size[1] as f32 / 2.0, size[2] as f32 / 2.0),
            )]
        }
        Shape::Bowl {
            radius,
            height,
            thickness,
        } => {
            let mut v = vec![(
                Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, -height / 2.0 + thickness / 2.0),
                    upright,
                ),
                SharedShape::cylinder((thickness / 2.0) as f32, (radius - thickness) as f32),
            )];
            // The rim: a ring of thin wall boxes, slightly overlapping so the wall is closed.
            let n = 12;
            let chord = 2.0 * radius * (std::f64::consts::PI / f64::from(n)).tan() * 1.05;
            for i in 0..n {
                let a = TAU * f64::from(i) / f64::from(n);
                let r = radius - thickness / 2.0;
                let pose = planar(r * a.cos(), r * a.sin(), thickness / 2.0, a);
                let half = [thickness / 2.0, chord / 2.0, (height - thickness) / 2.0].map(|x| x as f32);
                v.push((pose, SharedShape::cuboid(half[0], half[1], half[2])));
            }
            v
        }
        // Loaded with the assets (`Assets::load`), so the cache holds it.
        Shape::Mesh { ref file, scale, .. } => crate::mesh::cached(file, scale)
            .map(|m| vec![(Isometry3::identity(), m.hull.clone())])
            .unwrap_or_default(),
    }
}

/// Spawn one object as a dynamic body; its colliders carry `owner` and `index`.
pub fn spawn_object(
    world: &mut PhysicsWorld,
    mats: &mut Materials,
    model: &ObjectModel,
    color: [f32; 3],
    pose: Isometry3<f64>,
    owner: Owner,
    index: u32,
) -> RigidBodyHandle {
    let body = world.insert_body(
        RigidBodyBuilder::dynamic()
            .pose(iso_to_pose(&pose))
            .angular_damping(0.2)
            .user_data(index as u128),
    );
    let material = mats.add(Material::plain(color));
    let shapes = object_shapes(&model.shape);
    let mass = (model.mass / shapes.len() as f64) as f32;
    for (p, s) in shapes {
        let co = ColliderBuilder::new(s)
            .position(iso_to_pose(&p))
            .mass(mass)
            .friction(model.friction as f32)
            .collision_groups(owner.groups(false))
            .user_data(
                Tag {
                    material,
                    owner,
                    index,
                }
                .pack(),
            );
        world.insert_collider(co, Some(body));
    }
    body
}
