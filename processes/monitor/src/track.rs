//! A trajectory kept at bounded size: every point until the buffer fills, then every second one,
//! then every fourth... so a run of any length fits in a preallocated buffer without allocating.

/// A decimated polyline of at most `capacity` points (plus the latest point, kept separately).
#[derive(Debug, Clone)]
pub(crate) struct Track {
    points: Vec<[f32; 2]>,
    capacity: usize,
    /// Keep one offered point in `stride`.
    stride: u64,
    /// Points offered so far.
    offered: u64,
    last: Option<[f32; 2]>,
}

impl Track {
    /// An empty track holding at most `capacity` points (rounded up to an even number ≥ 2).
    pub fn new(capacity: usize) -> Track {
        let capacity = capacity.max(2).next_multiple_of(2);
        Track {
            points: Vec::with_capacity(capacity),
            capacity,
            stride: 1,
            offered: 0,
            last: None,
        }
    }

    /// Offers a point; keeps it when its index is a multiple of the stride. Never allocates.
    pub fn push(&mut self, x: f64, y: f64) {
        let p = [x as f32, y as f32];
        self.last = Some(p);
        if self.offered.is_multiple_of(self.stride) {
            if self.points.len() == self.capacity {
                // Keep the points at even positions: their indices are multiples of 2·stride.
                let half = self.capacity / 2;
                for i in 0..half {
                    self.points[i] = self.points[2 * i];
                }
                self.points.truncate(half);
                self.stride *= 2;
            }
            // With an even capacity the current index is a multiple of the doubled stride too.
            if self.offered.is_multiple_of(self.stride) {
                self.points.push(p);
            }
        }
        self.offered += 1;
    }

    /// The kept points followed by the latest one (when it was not kept).
    pub fn points(&self) -> impl Iterator<Item = [f32; 2]> + '_ {
        let tail = match (self.points.last(), self.last) {
            (Some(kept), Some(last)) if *kept == last => None,
            (_, last) => last,
        };
        self.points.iter().copied().chain(tail)
    }

    /// Points kept in the buffer.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.points.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_every_stride_th_point_and_stays_bounded() {
        let mut t = Track::new(10);
        for i in 0..1000 {
            t.push(i as f64, 0.0);
            assert!(t.len() <= 10);
        }
        let xs: Vec<f32> = t.points().map(|p| p[0]).collect();
        // 1000 points into 10 slots: stride 128, kept 0, 128, ..., 896, plus the latest 999.
        assert_eq!(
            xs,
            vec![0.0, 128.0, 256.0, 384.0, 512.0, 640.0, 768.0, 896.0, 999.0]
        );
        let steps: Vec<f32> = xs.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(steps[..steps.len() - 1].iter().all(|s| *s == 128.0));
    }

    #[test]
    fn short_tracks_are_kept_whole() {
        let mut t = Track::new(20_000);
        for i in 0..5 {
            t.push(i as f64, 2.0 * i as f64);
        }
        assert_eq!(t.points().count(), 5);
        assert_eq!(t.points().last(), Some([4.0, 8.0]));
    }
}
