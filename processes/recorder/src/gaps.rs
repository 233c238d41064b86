//! Samples lost before the recorder read them, counted from the headers' sequence numbers: a
//! realtime queue that overflowed drops its oldest samples, which shows as a gap in `seq`.
//!
//! A topic has one publisher, two while a hot swap runs the old and the new process side by
//! side (their sequences interleave), and a new one after a restart (its sequence starts over).
//! So up to two sequences are followed: a sample continues the one it follows exactly, else the
//! one with the highest number below it; a number below both starts a new publisher's sequence.

/// The sequences of one topic's publishers.
#[derive(Debug, Default, Clone)]
pub struct Gaps {
    last: [Option<u64>; 2],
    /// The slot a new publisher takes: the one not continued most recently.
    older: usize,
    lost: u64,
}

impl Gaps {
    /// Takes the sequence number of the next sample read; returns how many samples were lost
    /// just before it.
    pub fn observe(&mut self, seq: u64) -> u64 {
        let exact = (0..2).find(|&i| self.last[i].is_some_and(|s| s + 1 == seq));
        let below = (0..2)
            .filter(|&i| self.last[i].is_some_and(|s| s < seq))
            .max_by_key(|&i| self.last[i]);
        let (slot, lost) = match exact.or(below) {
            Some(i) => (i, seq - self.last[i].unwrap_or(0) - 1),
            None => (self.older, 0),
        };
        self.last[slot] = Some(seq);
        self.older = 1 - slot;
        self.lost += lost;
        lost
    }

    /// Samples lost so far.
    pub fn lost(&self) -> u64 {
        self.lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lost_over(seqs: &[u64]) -> u64 {
        let mut gaps = Gaps::default();
        seqs.iter().map(|&s| gaps.observe(s)).sum()
    }

    /// A queue that overflowed shows as a gap, counted once.
    #[test]
    fn an_overflow_is_counted() {
        assert_eq!(lost_over(&[0, 1, 2, 3]), 0);
        assert_eq!(lost_over(&[5, 6, 9, 10, 14]), 2 + 3);
    }

    /// A restart (the sequence starts over) and a hot swap (two sequences interleaved) lose
    /// nothing.
    #[test]
    fn restarts_and_interleaved_swaps_are_not_losses() {
        assert_eq!(lost_over(&[40, 41, 42, 0, 1, 2]), 0);
        assert_eq!(lost_over(&[500, 0, 501, 1, 502, 2, 3, 4]), 0);
        // After the swap the old sequence is stale; the new one passes it without a loss.
        let swap: Vec<u64> = [500, 0, 501].into_iter().chain(1..=700).collect();
        assert_eq!(lost_over(&swap), 0);
        // A restart after a swap reuses the stale slot.
        assert_eq!(lost_over(&[500, 0, 501, 1, 2, 0, 1, 2]), 0);
        assert_eq!(lost_over(&[500, 0, 501, 1, 4, 5]), 2);
    }
}
