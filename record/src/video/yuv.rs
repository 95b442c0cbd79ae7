//! RGB8 to YUV 4:2:0 (BT.601, limited range), the input both encoders take: one conversion,
//! so an AV1 and an H.264 video of the same frames show the same colours.

pub(super) fn chroma_size(width: u32, height: u32) -> (usize, usize) {
    (width.div_ceil(2) as usize, height.div_ceil(2) as usize)
}

/// BT.601 limited-range RGB → Y, and 2×2-averaged Cb, Cr (integer arithmetic, as swscale).
pub(super) fn rgb_to_yuv420(rgb: &[u8], w: usize, h: usize, yuv: &mut [Vec<u8>; 3]) {
    let px = |x: usize, y: usize| {
        let i = 3 * (y * w + x);
        (i32::from(rgb[i]), i32::from(rgb[i + 1]), i32::from(rgb[i + 2]))
    };
    for y in 0..h {
        for x in 0..w {
            let (r, g, b) = px(x, y);
            yuv[0][y * w + x] = (((66 * r + 129 * g + 25 * b + 128) >> 8) + 16) as u8;
        }
    }
    let cw = w.div_ceil(2);
    for cy in 0..h.div_ceil(2) {
        for cx in 0..cw {
            let (mut r, mut g, mut b, mut n) = (0, 0, 0, 0);
            for (x, y) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (px_x, px_y) = (2 * cx + x, 2 * cy + y);
                if px_x < w && px_y < h {
                    let p = px(px_x, px_y);
                    (r, g, b, n) = (r + p.0, g + p.1, b + p.2, n + 1);
                }
            }
            let (r, g, b) = (r / n, g / n, b / n);
            yuv[1][cy * cw + cx] = (((-38 * r - 74 * g + 112 * b + 128) >> 8) + 128) as u8;
            yuv[2][cy * cw + cx] = (((112 * r - 94 * g - 18 * b + 128) >> 8) + 128) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_white_and_black_map_to_bt601_limited_range() {
        let rgb = [0, 0, 0, 255, 255, 255, 128, 128, 128, 255, 255, 255];
        let mut yuv = [vec![0; 4], vec![0; 1], vec![0; 1]];
        rgb_to_yuv420(&rgb, 2, 2, &mut yuv);
        assert_eq!(yuv[0], vec![16, 235, 126, 235]);
        assert_eq!((yuv[1][0], yuv[2][0]), (128, 128));
    }
}
