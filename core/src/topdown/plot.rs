//! Where the robot went (docs/reference/pages.md): an episode's paths drawn over the scene's
//! top-down image. The base path is one colour per task, the key object's path a thin dark line,
//! each task's goal a ring of its tolerance radius in the task's colour, where the episode started
//! a dot, and where a failed task ended a cross in the task's colour with a dark outline.

use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder, Rgb, RgbImage};
use serde::{Deserialize, Serialize};

use crate::catalogue::Catalogue;
use crate::scene::Scene;

/// An episode's paths in the world frame (metres), as a worker sampled them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PathPlot {
    /// Base centre `[x, y]` and the task (plan index) it belongs to.
    pub base: Vec<([f32; 2], u32)>,
    /// The key object's centre at the same samples; `None` before the episode has one.
    pub object: Vec<Option<[f32; 2]>>,
    pub goals: Vec<PlotGoal>,
}

/// One task's goal and where it ended.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PlotGoal {
    pub task: u32,
    /// `nav`, `pick` or `place`.
    pub kind: String,
    pub at: [f32; 2],
    /// Ring radius, metres; 0 draws no ring.
    pub radius: f32,
    /// Base position when the task ended.
    pub end: [f32; 2],
    /// Whether the task failed (its end is marked).
    pub failed: bool,
}

/// Task colours, cycled: distinct on the light floor and the zone colours.
pub const TASK_COLOURS: [[u8; 3]; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
];
const DARK: Rgb<u8> = Rgb([25, 25, 25]);

/// The colour of task `i` in the plot.
pub fn task_colour(i: u32) -> [u8; 3] {
    TASK_COLOURS[i as usize % TASK_COLOURS.len()]
}

/// `scene` from above with `plot` drawn on it, as PNG bytes.
pub fn render_path_plot(scene: &Scene, catalogue: &Catalogue, px_per_m: u32, plot: &PathPlot) -> Vec<u8> {
    let mut img = super::render_image(scene, catalogue, px_per_m);
    let pen = Pen {
        ppm: f64::from(px_per_m.max(1)),
        room_y: scene.room.size[1],
    };
    for w in plot.object.windows(2) {
        if let [Some(a), Some(b)] = w {
            pen.line(&mut img, *a, *b, 1.2, DARK);
        }
    }
    for g in &plot.goals {
        if g.radius > 0.0 && finite(g.at) {
            let c = Rgb(task_colour(g.task));
            pen.ring(&mut img, g.at, f64::from(g.radius), 3.5, DARK);
            pen.ring(&mut img, g.at, f64::from(g.radius), 2.0, c);
        }
    }
    for w in plot.base.windows(2) {
        let ((a, _), (b, t)) = (w[0], w[1]);
        pen.line(&mut img, a, b, 3.0, Rgb(task_colour(t)));
    }
    // Where the episode started: a dark dot with the first task's colour inside.
    if let Some(&(p, t)) = plot.base.first().filter(|(p, _)| finite(*p)) {
        pen.dot(&mut img, pen.px(p), 5.0, DARK);
        pen.dot(&mut img, pen.px(p), 3.5, Rgb(task_colour(t)));
    }
    for g in plot.goals.iter().filter(|g| g.failed && finite(g.end)) {
        pen.cross(&mut img, g.end, 0.09, 4.5, DARK);
        pen.cross(&mut img, g.end, 0.08, 2.5, Rgb(task_colour(g.task)));
    }
    let mut png = Vec::new();
    PngEncoder::new(&mut png)
        .write_image(img.as_raw(), img.width(), img.height(), ExtendedColorType::Rgb8)
        .expect("encoding an in-memory RGB image as PNG cannot fail");
    png
}

fn finite(p: [f32; 2]) -> bool {
    p[0].is_finite() && p[1].is_finite()
}

/// World metres to pixels.
struct Pen {
    ppm: f64,
    room_y: f64,
}

impl Pen {
    fn px(&self, p: [f32; 2]) -> [f64; 2] {
        [
            f64::from(p[0]) * self.ppm,
            (self.room_y - f64::from(p[1])) * self.ppm,
        ]
    }

    /// A filled disc of `r` pixels at pixel position `c`.
    fn dot(&self, img: &mut RgbImage, c: [f64; 2], r: f64, colour: Rgb<u8>) {
        let (w, h) = (i64::from(img.width()), i64::from(img.height()));
        let (i0, i1) = ((c[0] - r).floor() as i64, (c[0] + r).ceil() as i64);
        let (j0, j1) = ((c[1] - r).floor() as i64, (c[1] + r).ceil() as i64);
        for j in j0.max(0)..=j1.min(h - 1) {
            for i in i0.max(0)..=i1.min(w - 1) {
                let (dx, dy) = (i as f64 + 0.5 - c[0], j as f64 + 0.5 - c[1]);
                if dx * dx + dy * dy <= r * r {
                    img.put_pixel(i as u32, j as u32, colour);
                }
            }
        }
    }

    /// A segment `width` pixels wide between world points.
    fn line(&self, img: &mut RgbImage, a: [f32; 2], b: [f32; 2], width: f64, colour: Rgb<u8>) {
        if !finite(a) || !finite(b) {
            return;
        }
        let (a, b) = (self.px(a), self.px(b));
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        // Past the image by far means garbage: draw nothing rather than loop for long.
        if len > 1e5 {
            return;
        }
        let n = (len * 2.0).ceil().max(1.0) as usize;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let p = [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
            self.dot(img, p, width / 2.0, colour);
        }
    }

    /// A circle of `radius` metres drawn `width` pixels wide.
    fn ring(&self, img: &mut RgbImage, c: [f32; 2], radius: f64, width: f64, colour: Rgb<u8>) {
        let centre = self.px(c);
        let r = radius * self.ppm;
        if !(r.is_finite() && r < 1e4) {
            return;
        }
        let n = (r * 8.0).ceil().max(16.0) as usize;
        for k in 0..n {
            let a = k as f64 / n as f64 * std::f64::consts::TAU;
            self.dot(
                img,
                [centre[0] + r * a.cos(), centre[1] + r * a.sin()],
                width / 2.0,
                colour,
            );
        }
    }

    /// An × of half-size `half` metres.
    fn cross(&self, img: &mut RgbImage, c: [f32; 2], half: f32, width: f64, colour: Rgb<u8>) {
        let (x, y) = (c[0], c[1]);
        self.line(img, [x - half, y - half], [x + half, y + half], width, colour);
        self.line(img, [x - half, y + half], [x + half, y - half], width, colour);
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

    /// A path across the room in two tasks, the second failed away from its goal.
    fn sample(scene: &Scene) -> PathPlot {
        let [rx, ry] = scene.room.size.map(|v| v as f32);
        let (a, b, c) = ([rx * 0.2, ry * 0.2], [rx * 0.5, ry * 0.5], [rx * 0.7, ry * 0.4]);
        let mut plot = PathPlot::default();
        for k in 0..=20 {
            let t = k as f32 / 20.0;
            let (p, task) = if k <= 10 {
                (
                    [a[0] + (b[0] - a[0]) * t * 2.0, a[1] + (b[1] - a[1]) * t * 2.0],
                    0,
                )
            } else {
                let t = t * 2.0 - 1.0;
                ([b[0] + (c[0] - b[0]) * t, b[1] + (c[1] - b[1]) * t], 1)
            };
            plot.base.push((p, task));
            plot.object.push((task == 1).then_some([p[0] + 0.1, p[1]]));
        }
        plot.goals = vec![
            PlotGoal {
                task: 0,
                kind: "nav".into(),
                at: b,
                radius: 0.10,
                end: b,
                failed: false,
            },
            PlotGoal {
                task: 1,
                kind: "place".into(),
                at: [rx * 0.8, ry * 0.6],
                radius: 0.05,
                end: c,
                failed: true,
            },
        ];
        plot
    }

    #[test]
    fn the_plot_draws_the_path_in_task_colours_on_the_scene() {
        let (scenes, cat) = content();
        let scene = &scenes[0];
        let plot = sample(scene);
        let png = render_path_plot(scene, &cat, 100, &plot);
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        let plain = super::super::render_image(scene, &cat, 100);
        assert_eq!((img.width(), img.height()), (plain.width(), plain.height()));
        let px = |p: [f32; 2]| {
            let [i, j] = Pen {
                ppm: 100.0,
                room_y: scene.room.size[1],
            }
            .px(p);
            *img.get_pixel(i as u32, j as u32)
        };
        // Midway along each task's leg, the task's colour.
        let (a, b) = (plot.base[5].0, plot.base[15].0);
        assert_eq!(px(a), Rgb(task_colour(0)));
        assert_eq!(px(b), Rgb(task_colour(1)));
        assert_ne!(img.as_raw(), plain.as_raw());
        if let Ok(dir) = std::env::var("KITCHEN_R_PLOT_PREVIEW") {
            std::fs::write(std::path::Path::new(&dir).join("path-plot.png"), &png).unwrap();
        }
    }

    #[test]
    fn garbage_points_draw_nothing_and_do_not_panic() {
        let (scenes, cat) = content();
        let plot = PathPlot {
            base: vec![([f32::NAN, 1.0], 0), ([1e9, -1e9], 0), ([-5.0, -5.0], 3)],
            object: vec![None, Some([f32::INFINITY, 0.0]), Some([1e30, 1e30])],
            goals: vec![PlotGoal {
                radius: 1e9,
                failed: true,
                end: [1e30, 0.0],
                ..Default::default()
            }],
        };
        render_path_plot(&scenes[0], &cat, 50, &plot);
    }
}
