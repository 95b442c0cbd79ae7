//! One frame of an episode video: the cameras side by side, a caption bar under them.
//!
//! The bar has two lines of 8×8 text (`font8x8`'s public-domain ASCII glyphs, drawn at 1×):
//! the task number of the plan's tasks (`2/5`, 1-based as the web pages number tasks) and its
//! sub-task sentence, then the sim
//! time and, once the task has ended, its outcome in green or red. Text that does not fit is cut
//! with `~`, so the frame size never depends on the text.

use font8x8::legacy::BASIC_LEGACY;

/// Pixels around and between the caption's lines.
const PAD: u32 = 4;
/// Glyph cell size.
const GLYPH: u32 = 8;
/// Height of the caption bar: two lines with padding.
pub const BAR_HEIGHT: u32 = 3 * PAD + 2 * GLYPH;

const BAR: [u8; 3] = [24, 24, 28];
const TEXT: [u8; 3] = [235, 235, 235];
const DIM: [u8; 3] = [160, 160, 170];
const GOOD: [u8; 3] = [90, 220, 110];
const BAD: [u8; 3] = [245, 90, 80];
/// Where a camera image is missing or of an unexpected size.
const EMPTY: [u8; 3] = [60, 60, 60];

/// How a task ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Succeeded, at this episode sim time (s).
    Success(f64),
    /// Failed, with the reason participants read on the submission page.
    Failed(String),
}

/// What the caption of one frame says.
#[derive(Debug, Clone, PartialEq)]
pub struct Caption<'a> {
    /// Task index from 0 (shown from 1).
    pub task: usize,
    pub tasks: usize,
    /// The sub-task sentence (`pick the bowl`).
    pub step: &'a str,
    /// Episode sim time of the frame (s).
    pub sim_time: f64,
    /// Set on the frames of a task's last second, once the task has ended.
    pub outcome: Option<&'a Outcome>,
}

impl Caption<'_> {
    /// The two lines of text and the colour of the second.
    pub fn lines(&self) -> (String, String, [u8; 3]) {
        // `6/6: move to the yellow zone` (the longest plan step) fits a 256-pixel line.
        let first = format!("{}/{}: {}", self.task + 1, self.tasks, self.step);
        let time = format!("t {:.1} s", self.sim_time);
        match self.outcome {
            None => (first, time, DIM),
            Some(Outcome::Success(at)) => (first, format!("{time}  SUCCESS at {at:.1} s"), GOOD),
            Some(Outcome::Failed(why)) => (first, format!("{time}  FAILED: {why}"), BAD),
        }
    }
}

/// The frame geometry for one set of camera sizes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameLayout {
    /// Each camera's `(x offset, width, height)`.
    cameras: Vec<(u32, u32, u32)>,
    pub width: u32,
    pub height: u32,
}

impl FrameLayout {
    /// Cameras of `sizes` (`width, height`) left to right, the caption bar under them. Both
    /// frame sides are even (4:2:0 video) and at least 16 (the encoder's minimum).
    pub fn new(sizes: &[(u32, u32)]) -> FrameLayout {
        let mut x = 0;
        let mut cameras = Vec::with_capacity(sizes.len());
        for &(w, h) in sizes {
            cameras.push((x, w, h));
            x += w;
        }
        let cam_h = sizes.iter().map(|s| s.1).max().unwrap_or(0);
        let even = |v: u32| v.max(16).next_multiple_of(2);
        FrameLayout {
            cameras,
            width: even(x),
            height: even(cam_h + BAR_HEIGHT),
        }
    }

    /// Characters one caption line holds.
    pub fn columns(&self) -> usize {
        ((self.width.saturating_sub(2 * PAD)) / GLYPH) as usize
    }

    /// Draw `images` (row-major RGB8, one per camera in layout order) and `caption` into `out`
    /// (resized to `width * height * 3`).
    pub fn compose(&self, images: &[&[u8]], caption: &Caption<'_>, out: &mut Vec<u8>) {
        let (w, h) = (self.width as usize, self.height as usize);
        out.clear();
        out.resize(w * h * 3, 0);
        let bar_top = self.height - BAR_HEIGHT;
        fill(out, w, (0, 0, self.width, bar_top), EMPTY);
        for (i, &(x0, cw, ch)) in self.cameras.iter().enumerate() {
            let (cw, ch) = (cw as usize, ch as usize);
            match images.get(i) {
                Some(img) if img.len() == cw * ch * 3 => {
                    for row in 0..ch {
                        let dst = (row * w + x0 as usize) * 3;
                        out[dst..dst + cw * 3].copy_from_slice(&img[row * cw * 3..(row + 1) * cw * 3]);
                    }
                }
                _ => {}
            }
        }
        fill(out, w, (0, bar_top, self.width, BAR_HEIGHT), BAR);
        let (first, second, colour) = caption.lines();
        let cols = self.columns();
        text(out, w, PAD, bar_top + PAD, &fit(&first, cols), TEXT);
        text(
            out,
            w,
            PAD,
            bar_top + 2 * PAD + GLYPH,
            &fit(&second, cols),
            colour,
        );
    }
}

/// `s` in at most `cols` characters, cut with `~` (the font has no ellipsis).
pub fn fit(s: &str, cols: usize) -> String {
    let n = s.chars().count();
    if n <= cols {
        return s.to_string();
    }
    let mut out: String = s.chars().take(cols.saturating_sub(1)).collect();
    out.push('~');
    out
}

fn fill(out: &mut [u8], stride: usize, (x, y, w, h): (u32, u32, u32, u32), rgb: [u8; 3]) {
    for row in y as usize..(y + h) as usize {
        for col in x as usize..(x + w) as usize {
            let at = (row * stride + col) * 3;
            if let Some(px) = out.get_mut(at..at + 3) {
                px.copy_from_slice(&rgb);
            }
        }
    }
}

/// Draw `s` with its top-left corner at `(x, y)`; characters outside ASCII show as `?`.
fn text(out: &mut [u8], stride: usize, x: u32, y: u32, s: &str, rgb: [u8; 3]) {
    for (i, c) in s.chars().enumerate() {
        let code = if c.is_ascii() { c as usize } else { '?' as usize };
        let glyph = BASIC_LEGACY[code];
        let gx = x as usize + i * GLYPH as usize;
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..GLYPH as usize {
                // Bit 0 is the glyph's leftmost pixel.
                if bits & (1 << col) != 0 {
                    let at = ((y as usize + row) * stride + gx + col) * 3;
                    if let Some(px) = out.get_mut(at..at + 3) {
                        px.copy_from_slice(&rgb);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn px(frame: &[u8], w: u32, x: u32, y: u32) -> [u8; 3] {
        let at = ((y * w + x) * 3) as usize;
        [frame[at], frame[at + 1], frame[at + 2]]
    }

    #[test]
    fn two_cameras_sit_side_by_side_over_an_even_sized_caption_bar() {
        let l = FrameLayout::new(&[(128, 128), (128, 128)]);
        assert_eq!((l.width, l.height), (256, 128 + BAR_HEIGHT));
        assert_eq!(l.height % 2, 0);
        let (a, b) = (vec![200u8; 128 * 128 * 3], vec![10u8; 128 * 128 * 3]);
        let cap = Caption {
            task: 1,
            tasks: 5,
            step: "pick the bowl",
            sim_time: 12.34,
            outcome: None,
        };
        let mut f = Vec::new();
        l.compose(&[&a, &b], &cap, &mut f);
        assert_eq!(f.len(), (l.width * l.height * 3) as usize);
        assert_eq!(px(&f, l.width, 5, 5), [200; 3]);
        assert_eq!(px(&f, l.width, 127, 127), [200; 3]);
        assert_eq!(px(&f, l.width, 128, 0), [10; 3]);
        assert_eq!(px(&f, l.width, 255, 127), [10; 3]);
        // The bar's corner is bar colour, and the first line has text-coloured pixels.
        assert_eq!(px(&f, l.width, 0, l.height - 1), BAR);
        let line = (0..l.width).flat_map(|x| (0..GLYPH).map(move |dy| (x, 128 + PAD + dy)));
        assert!(line.clone().any(|(x, y)| px(&f, l.width, x, y) == TEXT));
        // A camera image of the wrong size leaves its place grey instead of panicking.
        l.compose(&[&a[..10], &b], &cap, &mut f);
        assert_eq!(px(&f, l.width, 5, 5), EMPTY);
    }

    #[test]
    fn the_caption_numbers_tasks_from_one_and_shows_the_outcome_once_ended() {
        let failed = Outcome::Failed("time limit of 120 s reached".into());
        let mut cap = Caption {
            task: 0,
            tasks: 4,
            step: "move to the blue zone",
            sim_time: 3.04,
            outcome: None,
        };
        let (first, second, colour) = cap.lines();
        assert_eq!(first, "1/4: move to the blue zone");
        assert_eq!((second.as_str(), colour), ("t 3.0 s", DIM));
        cap.outcome = Some(&failed);
        let (_, second, colour) = cap.lines();
        assert_eq!(second, "t 3.0 s  FAILED: time limit of 120 s reached");
        assert_eq!(colour, BAD);
        let ok = Outcome::Success(3.1);
        cap.outcome = Some(&ok);
        assert_eq!(cap.lines().1, "t 3.0 s  SUCCESS at 3.1 s");
        assert_eq!(cap.lines().2, GOOD);
    }

    #[test]
    fn long_text_is_cut_to_the_line_and_a_glyph_lands_where_the_font_says() {
        assert_eq!(fit("abcdef", 4), "abc~");
        assert_eq!(fit("abc", 4), "abc");
        let mut f = vec![0u8; 16 * 8 * 3];
        text(&mut f, 16, 0, 0, "|", [255, 0, 0]);
        let lit: usize = (0..8 * 16).filter(|i| f[i * 3] == 255).count();
        let want: u32 = BASIC_LEGACY['|' as usize].iter().map(|b| b.count_ones()).sum();
        assert_eq!(lit, want as usize);
    }
}
