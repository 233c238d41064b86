//! ROS map_server maps: a YAML file (`image`, `resolution`, `origin`, `occupied_thresh`,
//! `free_thresh`, `negate`, `mode`) naming a PGM image (binary P5 or ASCII P2).
//!
//! A pixel is occupied when its occupancy `p` exceeds `occupied_thresh`, with
//! `p = (maxval − value) / maxval`, or `value / maxval` when `negate` is set (the map_server
//! convention: dark is occupied). Unknown pixels (between the thresholds) count as free. Image row
//! 0 is the top of the map; `origin` is the world position of the lower-left pixel's corner.

use mole_types::Square;
use std::path::{Path, PathBuf};

/// Largest image accepted (pixels), so a corrupt header cannot ask for gigabytes.
const MAX_PIXELS: usize = 16 * 1024 * 1024;

/// Why a ROS map could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// A file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The YAML file is malformed or misses a required key.
    #[error("{}:{line}: {message}", path.display())]
    Yaml {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// The image is not a PGM this reader understands.
    #[error("{}: {message}", path.display())]
    Image { path: PathBuf, message: String },
}

/// An occupancy map: which pixels are occupied, where the map sits and its pixel size.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyMap {
    pub width: usize,
    pub height: usize,
    /// Pixel size (m).
    pub resolution: f64,
    /// World position of the lower-left corner of the image (m).
    pub origin: (f64, f64),
    /// Row-major, row 0 at the top of the image (as stored in the PGM).
    pub occupied: Vec<bool>,
}

impl OccupancyMap {
    /// The upper-right corner of the map in the world frame: the arena a map implies.
    pub fn extent(&self) -> (f64, f64) {
        (
            self.origin.0 + self.width as f64 * self.resolution,
            self.origin.1 + self.height as f64 * self.resolution,
        )
    }

    /// One square of side `resolution` per occupied pixel, in the world frame.
    pub fn obstacles(&self) -> impl Iterator<Item = Square> + '_ {
        self.occupied
            .iter()
            .enumerate()
            .filter(|(_, occ)| **occ)
            .map(move |(i, _)| {
                let (col, row) = (i % self.width, i / self.width);
                let row_from_bottom = self.height - 1 - row;
                Square::new(
                    self.origin.0 + (col as f64 + 0.5) * self.resolution,
                    self.origin.1 + (row_from_bottom as f64 + 0.5) * self.resolution,
                    self.resolution,
                )
            })
    }
}

/// The keys of a map_server YAML file.
#[derive(Debug, Clone, PartialEq)]
pub struct MapYaml {
    pub image: String,
    pub resolution: f64,
    pub origin: [f64; 3],
    pub occupied_thresh: f64,
    pub free_thresh: f64,
    pub negate: bool,
}

/// Loads a map_server YAML file and the image it names (relative to the YAML's directory).
pub fn load_ros_map(yaml_path: &Path) -> Result<OccupancyMap, MapError> {
    let text = std::fs::read_to_string(yaml_path).map_err(|source| MapError::Read {
        path: yaml_path.to_path_buf(),
        source,
    })?;
    let yaml = parse_map_yaml(&text).map_err(|(line, message)| MapError::Yaml {
        path: yaml_path.to_path_buf(),
        line,
        message,
    })?;
    let image_path = yaml_path
        .parent()
        .unwrap_or_else(|| Path::new(""))
        .join(&yaml.image);
    let bytes = std::fs::read(&image_path).map_err(|source| MapError::Read {
        path: image_path.clone(),
        source,
    })?;
    let pgm = parse_pgm(&bytes).map_err(|message| MapError::Image {
        path: image_path,
        message,
    })?;
    Ok(occupancy(&yaml, &pgm))
}

/// Parses the map_server YAML subset: one `key: value` per line, `origin: [x, y, yaw]`.
/// Errors carry the 1-based line (0: a missing key).
pub fn parse_map_yaml(text: &str) -> Result<MapYaml, (usize, String)> {
    let mut image = None;
    let mut resolution = None;
    let mut origin = None;
    let mut occupied_thresh = 0.65;
    let mut free_thresh = 0.196;
    let mut negate = false;
    for (n, raw) in text.lines().enumerate() {
        let line_no = n + 1;
        let line = strip_comment(raw).trim();
        if line.is_empty() || line == "---" {
            continue;
        }
        let Some((key, value)) = line.split_once(':') else {
            return Err((line_no, format!("expected `key: value`, found `{line}`")));
        };
        let (key, value) = (key.trim(), unquote(value.trim()));
        let number = |v: &str| -> Result<f64, (usize, String)> {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| (line_no, format!("`{key}`: expected a number, found `{v}`")))
        };
        match key {
            "image" => image = Some(value.to_string()),
            "resolution" => {
                let r = number(value)?;
                if r <= 0.0 {
                    return Err((line_no, format!("`resolution`: expected > 0, found {r}")));
                }
                resolution = Some(r);
            }
            "origin" => {
                let inner = value
                    .strip_prefix('[')
                    .and_then(|v| v.strip_suffix(']'))
                    .ok_or_else(|| {
                        (
                            line_no,
                            format!("`origin`: expected [x, y, yaw], found `{value}`"),
                        )
                    })?;
                let parts: Vec<&str> = inner.split(',').map(str::trim).collect();
                if parts.len() != 3 {
                    return Err((
                        line_no,
                        format!("`origin`: expected [x, y, yaw], found `{value}`"),
                    ));
                }
                let o = [number(parts[0])?, number(parts[1])?, number(parts[2])?];
                if o[2] != 0.0 {
                    // Obstacles are axis-aligned squares: a rotated map cannot be represented.
                    return Err((line_no, format!("`origin`: expected yaw 0, found {}", o[2])));
                }
                origin = Some(o);
            }
            "occupied_thresh" => occupied_thresh = number(value)?,
            "free_thresh" => free_thresh = number(value)?,
            "negate" => {
                negate = match value {
                    "0" | "false" | "False" => false,
                    "1" | "true" | "True" => true,
                    _ => {
                        return Err((
                            line_no,
                            format!("`negate`: expected 0 or 1, found `{value}`"),
                        ));
                    }
                }
            }
            "mode" if value != "trinary" && value != "scale" => {
                return Err((
                    line_no,
                    format!("`mode`: expected trinary or scale, found `{value}`"),
                ));
            }
            // Other keys (e.g. written by newer map savers) do not change the occupancy.
            _ => {}
        }
    }
    if !(0.0..=1.0).contains(&occupied_thresh) {
        return Err((
            0,
            format!("`occupied_thresh`: expected a value in [0, 1], found {occupied_thresh}"),
        ));
    }
    Ok(MapYaml {
        image: image.ok_or((0, "missing key `image`".to_string()))?,
        resolution: resolution.ok_or((0, "missing key `resolution`".to_string()))?,
        origin: origin.ok_or((0, "missing key `origin`".to_string()))?,
        occupied_thresh,
        free_thresh,
        negate,
    })
}

fn strip_comment(line: &str) -> &str {
    let mut quote = None;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            (None, '#') => return &line[..i],
            _ => {}
        }
    }
    line
}

fn unquote(v: &str) -> &str {
    for q in ['"', '\''] {
        if let Some(inner) = v.strip_prefix(q).and_then(|v| v.strip_suffix(q)) {
            return inner;
        }
    }
    v
}

/// A greyscale image.
#[derive(Debug, Clone, PartialEq)]
pub struct Pgm {
    pub width: usize,
    pub height: usize,
    pub maxval: u16,
    /// Row-major samples, row 0 at the top.
    pub pixels: Vec<u16>,
}

/// Parses a PGM image, binary (P5, 8 or 16 bit) or ASCII (P2).
pub fn parse_pgm(bytes: &[u8]) -> Result<Pgm, String> {
    let mut pos = 0;
    let magic = next_token(bytes, &mut pos).ok_or("empty image")?;
    let binary = match magic {
        b"P5" => true,
        b"P2" => false,
        _ => return Err("expected a PGM image (P5 or P2)".to_string()),
    };
    let mut header = [0usize; 3];
    for (value, name) in header.iter_mut().zip(["width", "height", "maxval"]) {
        *value = next_token(bytes, &mut pos)
            .and_then(|t| std::str::from_utf8(t).ok())
            .and_then(|t| t.parse().ok())
            .ok_or_else(|| format!("PGM header: expected the {name}"))?;
    }
    let [width, height, maxval] = header;
    if width == 0 || height == 0 || width.saturating_mul(height) > MAX_PIXELS {
        return Err(format!("PGM size {width} × {height} is empty or too large"));
    }
    if maxval == 0 || maxval > 65535 {
        return Err(format!("PGM maxval {maxval} is outside 1..=65535"));
    }
    let n = width * height;
    let mut pixels = Vec::with_capacity(n);
    if binary {
        // Exactly one whitespace byte separates the header from the raster.
        pos += 1;
        let depth = if maxval < 256 { 1 } else { 2 };
        let raster = bytes
            .get(pos..pos + n * depth)
            .ok_or_else(|| format!("PGM raster truncated: expected {} bytes", n * depth))?;
        if depth == 1 {
            pixels.extend(raster.iter().map(|&b| b as u16));
        } else {
            pixels.extend(
                raster
                    .chunks_exact(2)
                    .map(|c| u16::from_be_bytes([c[0], c[1]])),
            );
        }
    } else {
        for i in 0..n {
            let v: usize = next_token(bytes, &mut pos)
                .and_then(|t| std::str::from_utf8(t).ok())
                .and_then(|t| t.parse().ok())
                .ok_or_else(|| format!("PGM raster: expected sample {i} of {n}"))?;
            pixels.push(v.min(65535) as u16);
        }
    }
    if let Some(i) = pixels.iter().position(|&p| p as usize > maxval) {
        return Err(format!("PGM sample {i} exceeds maxval {maxval}"));
    }
    Ok(Pgm {
        width,
        height,
        maxval: maxval as u16,
        pixels,
    })
}

/// The next whitespace-separated token of a PGM header, skipping `#` comments.
fn next_token<'a>(bytes: &'a [u8], pos: &mut usize) -> Option<&'a [u8]> {
    loop {
        while *pos < bytes.len() && bytes[*pos].is_ascii_whitespace() {
            *pos += 1;
        }
        if *pos < bytes.len() && bytes[*pos] == b'#' {
            while *pos < bytes.len() && bytes[*pos] != b'\n' {
                *pos += 1;
            }
            continue;
        }
        break;
    }
    let start = *pos;
    while *pos < bytes.len() && !bytes[*pos].is_ascii_whitespace() {
        *pos += 1;
    }
    (*pos > start).then(|| &bytes[start..*pos])
}

/// Applies the map_server thresholds to an image.
pub fn occupancy(yaml: &MapYaml, pgm: &Pgm) -> OccupancyMap {
    let maxval = f64::from(pgm.maxval);
    let occupied = pgm
        .pixels
        .iter()
        .map(|&v| {
            let v = f64::from(v);
            let p = if yaml.negate {
                v / maxval
            } else {
                (maxval - v) / maxval
            };
            p > yaml.occupied_thresh
        })
        .collect();
    OccupancyMap {
        width: pgm.width,
        height: pgm.height,
        resolution: yaml.resolution,
        origin: (yaml.origin[0], yaml.origin[1]),
        occupied,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const YAML: &str = "image: small.pgm\nresolution: 0.1  # metres\norigin: [1.0, 2.0, 0.0]\n\
                        negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n";

    #[test]
    fn yaml_keys_and_defaults() {
        let y = parse_map_yaml(YAML).unwrap();
        assert_eq!(y.image, "small.pgm");
        assert_eq!(y.resolution, 0.1);
        assert_eq!(y.origin, [1.0, 2.0, 0.0]);
        assert!(!y.negate);
        let y = parse_map_yaml("image: 'a b.pgm'\nresolution: 0.05\norigin: [0, 0, 0]\n").unwrap();
        assert_eq!(y.image, "a b.pgm");
        assert_eq!(y.occupied_thresh, 0.65);
    }

    #[test]
    fn yaml_errors_name_the_line() {
        assert_eq!(
            parse_map_yaml("image: a.pgm\norigin: [0, 0, 0]\n")
                .unwrap_err()
                .0,
            0
        );
        let e = parse_map_yaml("image: a.pgm\nresolution: fine\norigin: [0, 0, 0]\n").unwrap_err();
        assert_eq!(e.0, 2);
        assert!(e.1.contains("resolution"));
        let e = parse_map_yaml("image: a\nresolution: 1\norigin: [0, 0, 0.5]\n").unwrap_err();
        assert_eq!(e.0, 3);
        assert!(e.1.contains("yaw"));
        assert_eq!(
            parse_map_yaml("image: a\nresolution: 1\norigin: [0, 0]\n")
                .unwrap_err()
                .0,
            3
        );
        assert_eq!(parse_map_yaml("junk\n").unwrap_err().0, 1);
    }

    #[test]
    fn ascii_and_binary_pgm_agree() {
        let ascii = b"P2\n# a comment\n3 2\n255\n0 255 205\n255 10 255\n";
        let mut binary = b"P5 3 2 255\n".to_vec();
        binary.extend([0u8, 255, 205, 255, 10, 255]);
        let a = parse_pgm(ascii).unwrap();
        let b = parse_pgm(&binary).unwrap();
        assert_eq!(a, b);
        assert_eq!((a.width, a.height, a.maxval), (3, 2, 255));
        assert_eq!(a.pixels, vec![0, 255, 205, 255, 10, 255]);
        let mut wide = b"P5 2 1 1000\n".to_vec();
        wide.extend([0x03, 0xE8, 0x00, 0x01]);
        assert_eq!(parse_pgm(&wide).unwrap().pixels, vec![1000, 1]);
    }

    #[test]
    fn bad_images_are_refused() {
        assert!(parse_pgm(b"").is_err());
        assert!(parse_pgm(b"P6 1 1 255\n\0\0\0").is_err());
        assert!(
            parse_pgm(b"P5 2 2 255\n\0")
                .unwrap_err()
                .contains("truncated")
        );
        assert!(
            parse_pgm(b"P2 2 1 10\n3 11\n")
                .unwrap_err()
                .contains("exceeds")
        );
        assert!(parse_pgm(b"P2 0 1 10\n").is_err());
        assert!(
            parse_pgm(b"P2 100000 100000 255\n")
                .unwrap_err()
                .contains("too large")
        );
        assert!(
            parse_pgm(b"P2 2 1 255\n3\n")
                .unwrap_err()
                .contains("sample 1")
        );
    }

    #[test]
    fn dark_pixels_become_squares_in_the_world_frame() {
        let yaml = parse_map_yaml(YAML).unwrap();
        // Row 0 (top): black, white, unknown grey; row 1 (bottom): white, dark, white.
        let pgm = parse_pgm(b"P2 3 2 255\n0 255 205\n255 10 255\n").unwrap();
        let map = occupancy(&yaml, &pgm);
        assert_eq!(map.occupied, vec![true, false, false, false, true, false]);
        let squares: Vec<Square> = map.obstacles().collect();
        assert_eq!(squares.len(), 2);
        // Top-left pixel: column 0, second row from the bottom.
        assert!((squares[0].cx - 1.05).abs() < 1e-12 && (squares[0].cy - 2.15).abs() < 1e-12);
        assert!((squares[1].cx - 1.15).abs() < 1e-12 && (squares[1].cy - 2.05).abs() < 1e-12);
        assert_eq!(squares[0].side, 0.1);
        let (w, h) = map.extent();
        assert!((w - 1.3).abs() < 1e-12 && (h - 2.2).abs() < 1e-12);
        let negated = MapYaml {
            negate: true,
            ..yaml
        };
        let inv = occupancy(&negated, &pgm);
        assert_eq!(inv.occupied, vec![false, true, true, true, false, true]);
    }

    proptest! {
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
            let _ = parse_pgm(&bytes);
            let _ = parse_map_yaml(&String::from_utf8_lossy(&bytes));
        }

        #[test]
        fn random_headers_never_panic(w in 0usize..5, h in 0usize..5, m in 0usize..70000, p6 in any::<bool>()) {
            let mut bytes = format!("{} {w} {h} {m}\n", if p6 { "P5" } else { "P2" }).into_bytes();
            bytes.extend([7u8; 9]);
            let _ = parse_pgm(&bytes);
        }
    }
}
