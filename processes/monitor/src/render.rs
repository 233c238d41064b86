//! map.png: the run in one picture, drawn into an RGB buffer (y up) with a built-in 5×7 bitmap
//! font for the legend, so no font file is needed.

use crate::slam::confidence_ellipse;
use crate::{Monitor, Scene};
use mole_types::{CELL_FREE, CELL_OCCUPIED};

pub(crate) type Rgb = [u8; 3];

pub(crate) const WHITE: Rgb = [255, 255, 255];
pub(crate) const TEXT: Rgb = [20, 20, 20];
pub(crate) const UNEXPLORED: Rgb = [64, 64, 64];
pub(crate) const FREE: Rgb = [225, 225, 225];
pub(crate) const OCCUPIED: Rgb = [0, 0, 0];
pub(crate) const CONTACT: Rgb = [220, 30, 30];
pub(crate) const OBSTACLE: Rgb = [30, 60, 230];
pub(crate) const PLAN: Rgb = [230, 190, 0];
pub(crate) const PARTICLE: Rgb = [150, 80, 200];
pub(crate) const TRUE_TRACK: Rgb = [20, 170, 40];
pub(crate) const EST_TRACK: Rgb = [255, 140, 0];
pub(crate) const SMOOTHED_TRACK: Rgb = [0, 150, 255];
pub(crate) const START: Rgb = [0, 200, 200];
pub(crate) const GOAL: Rgb = [230, 0, 230];
pub(crate) const BEACON: Rgb = [0, 110, 110];
pub(crate) const LANDMARK: Rgb = [200, 20, 90];

/// Legend entries, in the order drawn.
pub(crate) const LEGEND: [(Rgb, &str); 14] = [
    (UNEXPLORED, "UNEXPLORED"),
    (FREE, "FREE"),
    (OCCUPIED, "OCCUPIED"),
    (CONTACT, "CONTACT CELL"),
    (OBSTACLE, "TRUE OBSTACLE"),
    (TRUE_TRACK, "TRUE PATH"),
    (EST_TRACK, "ESTIMATED PATH"),
    (SMOOTHED_TRACK, "SMOOTHED PATH"),
    (PLAN, "PLANNED PATH"),
    (PARTICLE, "PARTICLES"),
    (START, "START"),
    (GOAL, "GOAL"),
    (BEACON, "TRUE BEACON"),
    (LANDMARK, "LANDMARK, 95% ELLIPSE"),
];

const MARGIN: usize = 20;
const MAP_MAX_PX: f64 = 800.0;
const LEGEND_W: usize = 300;
const MIN_WIDTH: usize = 800;
const FONT_SCALE: usize = 2;
const ROW_H: usize = 24;

/// Where everything goes.
pub(crate) struct Layout {
    pub width: usize,
    pub height: usize,
    /// Pixels per metre.
    scale: f64,
    map_x0: usize,
    map_y0: usize,
    map_w: usize,
    map_h: usize,
    legend_x0: usize,
}

impl Layout {
    /// The map fits in 800 × 800 px at a uniform scale; the legend sits on its right.
    pub fn new(scene: &Scene) -> Layout {
        let scale = (MAP_MAX_PX / scene.arena_width).min(MAP_MAX_PX / scene.arena_height);
        let map_w = ((scene.arena_width * scale).round() as usize).clamp(1, MAP_MAX_PX as usize);
        let map_h = ((scene.arena_height * scale).round() as usize).clamp(1, MAP_MAX_PX as usize);
        let legend_h = (LEGEND.len() + 7) * ROW_H;
        Layout {
            width: (MARGIN + map_w + MARGIN + LEGEND_W + MARGIN).max(MIN_WIDTH),
            height: map_h.max(legend_h) + 2 * MARGIN,
            scale,
            map_x0: MARGIN,
            map_y0: MARGIN,
            map_w,
            map_h,
            legend_x0: MARGIN + map_w + MARGIN,
        }
    }

    /// Pixel (column, row) of a world point, y up; may lie outside the image.
    fn to_px(&self, x: f64, y: f64) -> (i64, i64) {
        let px = self.map_x0 as f64 + x * self.scale;
        let py = self.map_y0 as f64 + self.map_h as f64 - y * self.scale;
        // Clamped so that pixel arithmetic on far-away (or non-finite) points cannot overflow.
        let clamp = |v: f64| v.floor().clamp(-1e9, 1e9) as i64;
        (clamp(px), clamp(py))
    }
}

/// An RGB image, row-major from the top.
pub(crate) struct Canvas {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
    /// Drawing outside this rectangle is dropped (x0, y0, x1, y1), exclusive ends.
    clip: (i64, i64, i64, i64),
}

impl Canvas {
    fn new(width: usize, height: usize) -> Canvas {
        Canvas {
            width,
            height,
            rgb: WHITE.repeat(width * height),
            clip: (0, 0, width as i64, height as i64),
        }
    }

    fn set(&mut self, x: i64, y: i64, c: Rgb) {
        let (x0, y0, x1, y1) = self.clip;
        if x < x0 || y < y0 || x >= x1 || y >= y1 {
            return;
        }
        let i = 3 * (y as usize * self.width + x as usize);
        self.rgb[i..i + 3].copy_from_slice(&c);
    }

    fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Rgb) {
        let (cx0, cy0, cx1, cy1) = self.clip;
        for yy in y.max(cy0)..(y + h).min(cy1) {
            for xx in x.max(cx0)..(x + w).min(cx1) {
                self.set(xx, yy, c);
            }
        }
    }

    fn outline_rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, t: i64, c: Rgb) {
        self.fill_rect(x0, y0, x1 - x0 + 1, t, c);
        self.fill_rect(x0, y1 - t + 1, x1 - x0 + 1, t, c);
        self.fill_rect(x0, y0, t, y1 - y0 + 1, c);
        self.fill_rect(x1 - t + 1, y0, t, y1 - y0 + 1, c);
    }

    /// Bresenham's line with a square brush of side `t`.
    fn line(&mut self, (mut x0, mut y0): (i64, i64), (x1, y1): (i64, i64), t: i64, c: Rgb) {
        // Segments far outside the image (a diverged estimate) are not worth walking.
        let limit = 4 * (self.width + self.height) as i64;
        if [x0, y0, x1, y1]
            .iter()
            .any(|v| !(-limit..=limit).contains(v))
        {
            return;
        }
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let mut err = dx + dy;
        loop {
            self.fill_rect(x0 - t / 2, y0 - t / 2, t, t, c);
            if x0 == x1 && y0 == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x0 += sx;
            }
            if e2 <= dx {
                err += dx;
                y0 += sy;
            }
        }
    }

    fn disc(&mut self, (cx, cy): (i64, i64), r: i64, c: Rgb) {
        for y in -r..=r {
            for x in -r..=r {
                if x * x + y * y <= r * r {
                    self.set(cx + x, cy + y, c);
                }
            }
        }
    }

    fn ring(&mut self, (cx, cy): (i64, i64), r: i64, c: Rgb) {
        for y in -r..=r {
            for x in -r..=r {
                let d2 = x * x + y * y;
                if d2 <= r * r && d2 >= (r - 2) * (r - 2) {
                    self.set(cx + x, cy + y, c);
                }
            }
        }
    }

    /// Text in the 5×7 font, top-left at (x, y); lower case is drawn as upper case.
    fn text(&mut self, x: i64, y: i64, s: &str, c: Rgb) {
        let k_px = FONT_SCALE as i64;
        for (k, ch) in s.chars().enumerate() {
            let rows = glyph(ch);
            let gx = x + k as i64 * 6 * k_px;
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0b10000 >> col) != 0 {
                        self.fill_rect(gx + col * k_px, y + r as i64 * k_px, k_px, k_px, c);
                    }
                }
            }
        }
    }
}

/// Draws the whole picture.
pub(crate) fn draw(m: &Monitor) -> Canvas {
    let scene = m.scene();
    let l = Layout::new(scene);
    let mut cv = Canvas::new(l.width, l.height);
    let (gw, gh, res) = m.raster_size();
    let frontier = m.frontier_cells();
    let contact = m.contact_cells();

    // Cells: sample the cell under each map pixel's centre.
    for j in 0..l.map_h {
        let y = scene.arena_height - (j as f64 + 0.5) / l.scale;
        let row = ((y / res).floor().max(0.0) as usize).min(gh - 1);
        for i in 0..l.map_w {
            let x = (i as f64 + 0.5) / l.scale;
            let col = ((x / res).floor().max(0.0) as usize).min(gw - 1);
            let idx = row * gw + col;
            let mut c = match frontier.map(|g| g[idx]) {
                Some(CELL_FREE) => FREE,
                Some(CELL_OCCUPIED) => OCCUPIED,
                _ => UNEXPLORED,
            };
            if contact.is_some_and(|g| g[idx] == 1) {
                c = CONTACT;
            }
            cv.set((l.map_x0 + i) as i64, (l.map_y0 + j) as i64, c);
        }
    }

    // Everything in world coordinates stays inside the map panel.
    let (mx0, my0) = (l.map_x0 as i64, l.map_y0 as i64);
    cv.clip = (mx0, my0, mx0 + l.map_w as i64, my0 + l.map_h as i64);
    for sq in &scene.squares {
        let (min_x, min_y) = sq.min();
        let (max_x, max_y) = sq.max();
        let (x0, y1) = l.to_px(min_x, min_y);
        let (x1, y0) = l.to_px(max_x, max_y);
        cv.outline_rect(x0, y0, x1, y1, 2, OBSTACLE);
    }
    cv.outline_rect(
        mx0,
        my0,
        mx0 + l.map_w as i64 - 1,
        my0 + l.map_h as i64 - 1,
        2,
        OBSTACLE,
    );
    for p in m.particle_points() {
        let (x, y) = l.to_px(f64::from(p[0]), f64::from(p[1]));
        cv.fill_rect(x, y, 2, 2, PARTICLE);
    }
    polyline(&mut cv, &l, m.plan_points().iter().copied(), 2, PLAN);
    polyline(&mut cv, &l, m.true_points(), 2, TRUE_TRACK);
    polyline(&mut cv, &l, m.estimated_points(), 2, EST_TRACK);
    polyline(
        &mut cv,
        &l,
        m.smoothed_points().iter().copied(),
        2,
        SMOOTHED_TRACK,
    );
    for b in &scene.beacons {
        let (x, y) = l.to_px(b.x, b.y);
        cv.fill_rect(x - 5, y - 5, 11, 11, TEXT);
        cv.fill_rect(x - 4, y - 4, 9, 9, BEACON);
    }
    for lm in m.landmark_estimates() {
        if let Some(e) = confidence_ellipse(&lm.covariance) {
            polyline(&mut cv, &l, ellipse_points(lm.x, lm.y, &e), 2, LANDMARK);
        }
        cv.disc(l.to_px(lm.x, lm.y), 3, LANDMARK);
    }
    cv.disc(l.to_px(scene.start.0, scene.start.1), 7, TEXT);
    cv.disc(l.to_px(scene.start.0, scene.start.1), 5, START);
    if let Some((gx, gy)) = scene.goal {
        let r = ((scene.goal_tolerance * l.scale).round() as i64).max(8);
        cv.ring(l.to_px(gx, gy), r, GOAL);
        cv.disc(l.to_px(gx, gy), 5, GOAL);
    }

    // Legend.
    cv.clip = (0, 0, l.width as i64, l.height as i64);
    let (lx, mut ly) = (l.legend_x0 as i64, l.map_y0 as i64);
    for (colour, label) in LEGEND {
        cv.fill_rect(lx, ly, 28, 14, TEXT);
        cv.fill_rect(lx + 1, ly + 1, 26, 12, colour);
        cv.text(lx + 38, ly, label, TEXT);
        ly += ROW_H as i64;
    }
    // Scale bar: the longest round length that fits in 160 px.
    let bar_m = [10.0, 5.0, 2.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01]
        .into_iter()
        .find(|m| m * l.scale <= 160.0)
        .unwrap_or(0.01);
    let bar_px = ((bar_m * l.scale).round() as i64).max(2);
    cv.fill_rect(lx, ly + 5, bar_px, 4, TEXT);
    cv.text(lx + bar_px + 10, ly, &format!("{bar_m} M"), TEXT);
    ly += 2 * ROW_H as i64;
    for line in m.status_lines() {
        cv.text(lx, ly, &line, TEXT);
        ly += ROW_H as i64;
    }
    cv
}

/// Segments of a drawn ellipse.
const ELLIPSE_SEGMENTS: usize = 48;

/// The closed outline of an ellipse centred on (x, y), in world points.
fn ellipse_points(x: f64, y: f64, e: &crate::slam::Ellipse) -> impl Iterator<Item = [f32; 2]> + '_ {
    let (sin, cos) = e.angle.sin_cos();
    (0..=ELLIPSE_SEGMENTS).map(move |k| {
        let t = std::f64::consts::TAU * k as f64 / ELLIPSE_SEGMENTS as f64;
        let (u, v) = (e.major * t.cos(), e.minor * t.sin());
        [
            (x + cos * u - sin * v) as f32,
            (y + sin * u + cos * v) as f32,
        ]
    })
}

/// Joins consecutive world points with line segments.
fn polyline(cv: &mut Canvas, l: &Layout, pts: impl Iterator<Item = [f32; 2]>, t: i64, c: Rgb) {
    let mut prev: Option<(i64, i64)> = None;
    for p in pts {
        let q = l.to_px(f64::from(p[0]), f64::from(p[1]));
        match prev {
            Some(a) => cv.line(a, q, t, c),
            None => cv.line(q, q, t, c),
        }
        prev = Some(q);
    }
}

/// The 5×7 bitmap of a character (bit 4 is the leftmost column); unknown characters draw `?`.
fn glyph(ch: char) -> [u8; 7] {
    match ch.to_ascii_uppercase() {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1E],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x0A, 0x04, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        ' ' => [0; 7],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glyphs_fit_five_columns_and_differ() {
        let chars = "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.,:-=%/()";
        let mut seen = std::collections::HashSet::new();
        for ch in chars.chars() {
            let g = glyph(ch);
            assert!(g.iter().all(|r| *r < 32), "{ch}");
            assert!(seen.insert(g), "{ch} duplicates another glyph");
        }
        assert_eq!(glyph('a'), glyph('A'));
    }

    #[test]
    fn text_draws_pixels_in_its_colour() {
        let mut cv = Canvas::new(40, 20);
        cv.text(1, 1, "I", TEXT);
        // 'I' row 0 is 01110: columns 1..=3, scaled ×2 → pixels x = 1 + 2..8.
        let px = |x: usize, y: usize| &cv.rgb[3 * (y * 40 + x)..3 * (y * 40 + x) + 3];
        assert_eq!(px(3, 1), TEXT);
        assert_eq!(px(1, 1), WHITE);
    }
}
