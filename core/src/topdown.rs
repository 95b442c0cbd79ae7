//! Top-down scene images for VLM planners (paper, Language Instructions: "a top-down image of
//! each scene ... colored areas mark locations where objects can be placed or taken from").
//!
//! An orthographic view from above, north (+y) up, one pixel per `1 / px_per_m` metres, the image
//! covering exactly the room's inner floor. Painted back to front: floor, furniture footprints in
//! their colours with a darker outline (sinks and stoves get a basin and burners so a reader can
//! tell them apart), zones in their `rgb` colour, key objects at their start positions as glyphs
//! (one silhouette per model type in the object's colour, with a dark outline and a light halo
//! so type and colour read on any zone; see [`Glyph`]), and the walls as a frame along the
//! border. The zone colours exist only here: the robot's cameras never
//! see them. Pure pixel arithmetic, so the same scene always gives the same PNG bytes.

use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder, Rgb, RgbImage};

use crate::catalogue::Catalogue;
use crate::scene::{Furniture, FurnitureKind, Scene};

mod glyph;
mod plot;

pub use glyph::Glyph;
use glyph::{HALO, OUTLINE, Paint};
pub use plot::{PathPlot, PlotGoal, TASK_COLOURS, render_path_plot, task_colour};

/// The resolution the CLI and server use unless told otherwise.
pub const DEFAULT_PX_PER_M: u32 = 100;
/// How much outlines darken the fill colour.
const OUTLINE_SHADE: f32 = 0.55;

/// Render `scene` seen from above as PNG bytes of `room.size * px_per_m` pixels.
pub fn render_topdown(scene: &Scene, catalogue: &Catalogue, px_per_m: u32) -> Vec<u8> {
    let img = render_image(scene, catalogue, px_per_m);
    let mut png = Vec::new();
    PngEncoder::new(&mut png)
        .write_image(img.as_raw(), img.width(), img.height(), ExtendedColorType::Rgb8)
        .expect("encoding an in-memory RGB image as PNG cannot fail");
    png
}

/// The raw image behind [`render_topdown`].
pub fn render_image(scene: &Scene, catalogue: &Catalogue, px_per_m: u32) -> RgbImage {
    let ppm = f64::from(px_per_m.max(1));
    let mut c = Canvas {
        img: RgbImage::from_pixel(
            (scene.room.size[0] * ppm).round().max(1.0) as u32,
            (scene.room.size[1] * ppm).round().max(1.0) as u32,
            rgb8(scene.room.floor_color, 1.0),
        ),
        ppm,
        room_y: scene.room.size[1],
        line: (1.5 / ppm).max(0.015),
    };
    for f in &scene.furniture {
        c.furniture(f);
    }
    for z in &scene.zones {
        let (h, fill, edge) = (
            [z.size[0] / 2.0, z.size[1] / 2.0],
            rgb8(z.rgb, 1.0),
            rgb8(z.rgb, 0.7),
        );
        c.rect([z.center[0], z.center[1], 0.0], h, fill, edge);
    }
    for o in &scene.key_objects {
        let Some(m) = catalogue.model(&o.model) else {
            continue;
        };
        let Some(p) = scene.key_object_start(o, 0.0) else {
            continue;
        };
        let colour = o
            .variant
            .as_ref()
            .and_then(|v| m.variants.get(v))
            .copied()
            .unwrap_or(m.color);
        c.glyph(&Glyph::of(&m.id, &m.shape), [p[0], p[1], o.yaw], colour);
    }
    c.walls(scene);
    c.img
}

fn rgb8(c: [f32; 3], shade: f32) -> Rgb<u8> {
    Rgb(c.map(|v| ((v * shade).clamp(0.0, 1.0) * 255.0).round() as u8))
}

struct Canvas {
    img: RgbImage,
    ppm: f64,
    room_y: f64,
    /// Outline width, metres.
    line: f64,
}

impl Canvas {
    /// World centre of pixel `(i, j)`; rows run from north (top) to south.
    fn world(&self, i: u32, j: u32) -> [f64; 2] {
        [
            (f64::from(i) + 0.5) / self.ppm,
            self.room_y - (f64::from(j) + 0.5) / self.ppm,
        ]
    }

    /// Paint every pixel within `reach` metres of `centre` for which `colour` says so.
    fn paint(&mut self, centre: [f64; 2], reach: f64, colour: impl Fn([f64; 2]) -> Option<Rgb<u8>>) {
        let (w, h) = (self.img.width(), self.img.height());
        let px = |v: f64| (v * self.ppm).floor().max(0.0) as u32;
        let (i0, i1) = (px(centre[0] - reach), px(centre[0] + reach).min(w - 1));
        let (j0, j1) = (
            px(self.room_y - centre[1] - reach),
            px(self.room_y - centre[1] + reach).min(h - 1),
        );
        for j in j0..=j1 {
            for i in i0..=i1 {
                if let Some(c) = colour(self.world(i, j)) {
                    self.img.put_pixel(i, j, c);
                }
            }
        }
    }

    /// A rectangle of half extents `half` centred at `pose = [x, y, yaw]`, with an outline.
    fn rect(&mut self, pose: [f64; 3], half: [f64; 2], fill: Rgb<u8>, edge: Rgb<u8>) {
        // Thin things (a fork) keep a visible fill.
        let line = self.line.min(half[0].min(half[1]) / 3.0);
        let (s, c) = pose[2].sin_cos();
        self.paint([pose[0], pose[1]], half[0].hypot(half[1]), |p| {
            let (dx, dy) = (p[0] - pose[0], p[1] - pose[1]);
            let (lx, ly) = ((c * dx + s * dy).abs(), (-s * dx + c * dy).abs());
            let inside = lx <= half[0] && ly <= half[1];
            let core = lx <= half[0] - line && ly <= half[1] - line;
            inside.then_some(if core { fill } else { edge })
        });
    }

    fn disc(&mut self, centre: [f64; 2], r: f64, fill: Rgb<u8>, edge: Rgb<u8>) {
        let line = self.line.min(r / 3.0);
        self.paint(centre, r, |p| {
            let d = (p[0] - centre[0]).hypot(p[1] - centre[1]);
            (d <= r).then_some(if d <= r - line { fill } else { edge })
        });
    }

    /// A key object's glyph at `pose = [x, y, yaw]`, filled with `colour`.
    fn glyph(&mut self, g: &Glyph, pose: [f64; 3], colour: [f32; 3]) {
        // Outline and halo at least a pixel and a half each, so they survive small images.
        let line = (1.5 / self.ppm).max(0.008);
        let (s, c) = pose[2].sin_cos();
        self.paint([pose[0], pose[1]], g.reach + 2.0 * line, |p| {
            let (dx, dy) = (p[0] - pose[0], p[1] - pose[1]);
            let local = [c * dx + s * dy, -s * dx + c * dy];
            g.paint(local, line).map(|paint| match paint {
                Paint::Fill => rgb8(colour, 1.0),
                Paint::Shade(k) => rgb8(colour, k),
                Paint::Outline => Rgb(OUTLINE),
                Paint::Halo => Rgb(HALO),
            })
        });
    }

    fn furniture(&mut self, f: &Furniture) {
        let [sx, sy, _] = f.scaled_size();
        let [x, y, yaw] = f.pose;
        self.rect(
            f.pose,
            [sx / 2.0, sy / 2.0],
            rgb8(f.color, 1.0),
            rgb8(f.color, OUTLINE_SHADE),
        );
        // Details in the piece's own frame, so a rotated sink still shows its basin.
        let (s, c) = yaw.sin_cos();
        let at = |lx: f64, ly: f64| [x + c * lx - s * ly, y + s * lx + c * ly];
        let inner = rgb8(f.color, 0.8);
        match f.kind {
            FurnitureKind::Sink => {
                let p = at(0.0, 0.0);
                let half = [sx / 2.0 - 0.1, sy / 2.0 - 0.1];
                self.rect([p[0], p[1], yaw], half, rgb8(f.color, 1.15), inner);
            }
            FurnitureKind::Stove => {
                let r = (sx.min(sy) / 4.0 - 0.03).max(0.03);
                for (kx, ky) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                    let p = at(kx * sx / 4.0, ky * sy / 4.0);
                    self.disc(p, r, rgb8([0.35, 0.35, 0.37], 1.0), rgb8([0.6, 0.6, 0.62], 1.0));
                }
            }
            _ => {}
        }
    }

    fn walls(&mut self, scene: &Scene) {
        let [rx, ry] = scene.room.size;
        let t = (scene.room.wall_thickness).max(2.0 / self.ppm);
        let colour = rgb8(scene.room.wall_color, OUTLINE_SHADE);
        self.paint([rx / 2.0, ry / 2.0], rx.hypot(ry), |p| {
            (p[0] < t || p[1] < t || p[0] > rx - t || p[1] > ry - t).then_some(colour)
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn content() -> (Vec<Scene>, Catalogue) {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        (Scene::load_all(&dir.join("scenes"), &cat).unwrap(), cat)
    }

    /// Pixel of world point `p`.
    fn pixel(img: &RgbImage, scene: &Scene, ppm: u32, p: [f64; 2]) -> Rgb<u8> {
        let ppm = f64::from(ppm);
        let (i, j) = ((p[0] * ppm) as u32, ((scene.room.size[1] - p[1]) * ppm) as u32);
        *img.get_pixel(i, j)
    }

    #[test]
    fn zones_are_painted_in_their_colour() {
        let (scenes, cat) = content();
        for scene in &scenes {
            let png = render_topdown(scene, &cat, 50);
            let img = image::load_from_memory(&png).unwrap().to_rgb8();
            let [rx, ry] = scene.room.size;
            assert_eq!(
                (img.width(), img.height()),
                ((rx * 50.0) as u32, (ry * 50.0) as u32)
            );
            // Key objects may cover a zone's centre; without them the centre shows the zone.
            let mut bare = scene.clone();
            bare.key_objects.clear();
            let img = render_image(&bare, &cat, 50);
            for z in &scene.zones {
                assert_eq!(
                    pixel(&img, scene, 50, z.center),
                    rgb8(z.rgb, 1.0),
                    "{} {}",
                    scene.id,
                    z.color
                );
            }
        }
    }

    /// Pixels within `r` metres of world point `p`.
    fn around(img: &RgbImage, scene: &Scene, ppm: u32, p: [f64; 2], r: f64) -> Vec<Rgb<u8>> {
        let steps = (r * f64::from(ppm)).ceil() as i32;
        let mut out = Vec::new();
        for dj in -steps..=steps {
            for di in -steps..=steps {
                let q = [
                    p[0] + f64::from(di) / f64::from(ppm),
                    p[1] + f64::from(dj) / f64::from(ppm),
                ];
                if (q[0] - p[0]).hypot(q[1] - p[1]) <= r {
                    out.push(pixel(img, scene, ppm, q));
                }
            }
        }
        out
    }

    fn colour_of(cat: &Catalogue, o: &crate::scene::KeyObject) -> [f32; 3] {
        let m = cat.model(&o.model).unwrap();
        o.variant.as_ref().map_or(m.color, |v| m.variants[v])
    }

    #[test]
    fn key_objects_are_drawn_at_their_start() {
        let (scenes, cat) = content();
        for scene in &scenes {
            let img = render_image(scene, &cat, 100);
            for o in &scene.key_objects {
                let p = scene.key_object_start(o, 0.0).unwrap();
                let near = around(&img, scene, 100, [p[0], p[1]], 0.03);
                let fill = rgb8(colour_of(&cat, o), 1.0);
                assert!(near.contains(&fill), "{} {}", scene.id, o.name());
            }
        }
    }

    /// An object on a zone painted in the object's own colour still stands out: its outline
    /// and halo differ from the zone, and enough of them surround it.
    #[test]
    fn objects_stay_visible_on_a_zone_of_their_colour() {
        let (scenes, cat) = content();
        for scene in &scenes {
            let mut same = scene.clone();
            for o in &scene.key_objects {
                let colour = colour_of(&cat, o);
                let z = same.zones.iter_mut().find(|z| z.color == o.zone).unwrap();
                z.rgb = colour;
                let img = render_image(&same, &cat, 100);
                let p = scene.key_object_start(o, 0.0).unwrap();
                let near = around(&img, &same, 100, [p[0], p[1]], 0.16);
                let zone = rgb8(colour, 1.0);
                assert_ne!(Rgb(glyph::OUTLINE), zone);
                assert_ne!(Rgb(glyph::HALO), zone);
                let outline = near.iter().filter(|c| **c == Rgb(glyph::OUTLINE)).count();
                let halo = near.iter().filter(|c| **c == Rgb(glyph::HALO)).count();
                assert!(
                    outline >= 20 && halo >= 20,
                    "{} {}: {outline} {halo}",
                    scene.id,
                    o.name()
                );
                same.zones.clone_from(&scene.zones);
            }
        }
    }

    /// Each key model type has its own silhouette (or inner detail), at one colour and size.
    #[test]
    fn key_object_types_differ_in_shape() {
        let (_, cat) = content();
        let grid = |g: &Glyph| -> Vec<Option<glyph::Paint>> {
            let mut v = Vec::new();
            for j in -50..=50 {
                for i in -50..=50 {
                    v.push(g.paint([f64::from(i) * 0.004, f64::from(j) * 0.004], 0.01));
                }
            }
            v
        };
        let types = ["apple", "bowl", "cup", "fork", "plate"];
        let masks: Vec<_> = (types.iter())
            .map(|t| grid(&Glyph::of(t, &cat.model(t).unwrap().shape)))
            .collect();
        for a in 0..types.len() {
            for b in a + 1..types.len() {
                let differ = (masks[a].iter().zip(&masks[b])).filter(|(x, y)| x != y).count();
                assert!(
                    differ > 100,
                    "{} and {} look alike ({differ})",
                    types[a],
                    types[b]
                );
            }
        }
        // Also at one common size: the silhouettes themselves differ, not only the scale.
        let unit = crate::catalogue::Shape::Sphere { radius: 0.09 };
        let masks: Vec<_> = types.iter().map(|t| grid(&Glyph::of(t, &unit))).collect();
        for a in 0..types.len() {
            for b in a + 1..types.len() {
                assert_ne!(masks[a], masks[b], "{} and {}", types[a], types[b]);
            }
        }
    }

    #[test]
    fn rendering_is_deterministic() {
        let (scenes, cat) = content();
        assert_eq!(
            render_topdown(&scenes[0], &cat, 40),
            render_topdown(&scenes[0], &cat, 40)
        );
    }

    /// Not a check: `cargo test -p kitchen-r-core -- --ignored write_topdown_previews` writes the
    /// images to the system temp directory for a look.
    #[test]
    #[ignore]
    fn write_topdown_previews() {
        let (scenes, cat) = content();
        for s in &scenes {
            let path = std::env::temp_dir().join(format!("topdown_{}.png", s.id));
            std::fs::write(path, render_topdown(s, &cat, DEFAULT_PX_PER_M)).unwrap();
        }
    }
}
