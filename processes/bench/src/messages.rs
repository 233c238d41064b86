//! The benchmark's message types: one payload type per size (header + bytes, `N` bytes in all)
//! and the small acknowledgement the probes send back.

use bytemuck::{Pod, Zeroable};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use mole_types::{Header, Invalid, Message};

/// Bytes of the common header at the start of every message.
pub const HEADER_BYTES: usize = core::mem::size_of::<Header>();

/// The sizes `mole bench ipc` measures by default (4 KiB is `mole bench peers`').
pub const IPC_SIZES: &[usize] = &[64, 1024, 16 * 1024, 256 * 1024, 1024 * 1024, 4 << 20];

/// Every payload size (whole message, header included) the benchmark has a type for.
pub const SUPPORTED_SIZES: &[usize] =
    &[64, 1024, 4096, 16 * 1024, 256 * 1024, 1024 * 1024, 4 << 20];

/// A payload message: the header, then `SIZE − 32` bytes the sender writes in place.
pub trait BenchMessage: Message {
    /// Whole message size in bytes.
    const SIZE: usize;
    /// The bytes after the header.
    fn payload_mut(&mut self) -> &mut [u8];
}

/// Declares one payload type of `$size` bytes in all, named `$type_name` on the wire.
macro_rules! bench_message {
    ($name:ident, $size:expr, $type_name:tt) => {
        #[doc = concat!("A ", stringify!($size), "-byte benchmark message (`", $type_name, "`).")]
        #[repr(C)]
        #[derive(Clone, Copy, Pod, Zeroable, ZeroCopySend, Message)]
        #[type_name($type_name)]
        #[layout(size = $size)]
        pub struct $name {
            pub header: Header,
            /// Every byte pattern of a payload is meaningful.
            pub payload: [u8; $size - HEADER_BYTES],
        }

        // A derived Debug would print megabytes; the size and header say enough.
        impl core::fmt::Debug for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.debug_struct(stringify!($name))
                    .field("header", &self.header)
                    .field("payload_bytes", &self.payload.len())
                    .finish()
            }
        }

        impl BenchMessage for $name {
            const SIZE: usize = $size;
            fn payload_mut(&mut self) -> &mut [u8] {
                &mut self.payload
            }
        }
    };
}

bench_message!(Bench64, 64, "mole.Bench64.v1");
bench_message!(Bench1K, 1024, "mole.Bench1K.v1");
bench_message!(Bench4K, 4096, "mole.Bench4K.v1");
bench_message!(Bench16K, 16384, "mole.Bench16K.v1");
bench_message!(Bench256K, 262144, "mole.Bench256K.v1");
bench_message!(Bench1M, 1048576, "mole.Bench1M.v1");
bench_message!(Bench4M, 4194304, "mole.Bench4M.v1");

/// Runs `$body` with `$M` bound to the payload type of `$size` bytes; an unknown size is a
/// [`crate::BenchError::UnsupportedSize`].
macro_rules! with_message_type {
    ($size:expr, $M:ident => $body:expr) => {
        match $size {
            64 => {
                type $M = $crate::messages::Bench64;
                $body
            }
            1024 => {
                type $M = $crate::messages::Bench1K;
                $body
            }
            4096 => {
                type $M = $crate::messages::Bench4K;
                $body
            }
            16384 => {
                type $M = $crate::messages::Bench16K;
                $body
            }
            262144 => {
                type $M = $crate::messages::Bench256K;
                $body
            }
            1048576 => {
                type $M = $crate::messages::Bench1M;
                $body
            }
            4194304 => {
                type $M = $crate::messages::Bench4M;
                $body
            }
            other => Err($crate::BenchError::UnsupportedSize(other)),
        }
    };
}
pub(crate) use with_message_type;

/// What a probe sends back: the receipt of one message (latency, fan-out) or the totals of a
/// throughput run. Also the socket transports' 80-byte ack frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.BenchAck.v1")]
#[layout(size = 80)]
#[message(check = BenchAck::check)]
pub struct BenchAck {
    pub header: Header,
    /// Sequence number of the acknowledged message.
    pub seq: u64,
    /// When the acknowledged message was sent (its `stamp_ns`, CLOCK_MONOTONIC).
    pub send_ns: u64,
    /// When the probe received it (throughput: the last message's receipt).
    pub recv_ns: u64,
    /// Throughput: receipt time of the first counted message.
    pub first_ns: u64,
    /// Throughput: messages received.
    pub count: u64,
    /// Which probe acknowledges (fan-out).
    pub probe: u32,
    pub _pad: u32,
}

impl BenchAck {
    /// Copies everything but the header (the publisher stamps that).
    pub fn copy_body_into(&self, dst: &mut BenchAck) {
        dst.seq = self.seq;
        dst.send_ns = self.send_ns;
        dst.recv_ns = self.recv_ns;
        dst.first_ns = self.first_ns;
        dst.count = self.count;
        dst.probe = self.probe;
        dst._pad = 0;
    }
}

impl BenchAck {
    /// A throughput total ends after it starts (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.recv_ns < self.first_ns {
            return Err(Invalid::OutOfRange("recv_ns"));
        }
        Ok(())
    }
}

/// Whether `size` has a payload type.
pub fn is_supported(size: usize) -> bool {
    SUPPORTED_SIZES.contains(&size)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn size_of_type(size: usize) -> Result<(usize, &'static str), crate::BenchError> {
        with_message_type!(size, M => Ok((core::mem::size_of::<M>(), M::wire_type_name())))
    }

    #[test]
    fn every_supported_size_has_a_type_of_that_size_and_its_own_name() {
        let mut names = Vec::new();
        for &size in SUPPORTED_SIZES {
            let (bytes, name) = size_of_type(size).expect("supported");
            assert_eq!(bytes, size);
            names.push(name);
        }
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), SUPPORTED_SIZES.len());
    }

    #[test]
    fn unknown_sizes_are_refused() {
        assert!(matches!(
            size_of_type(100),
            Err(crate::BenchError::UnsupportedSize(100))
        ));
        assert!(!is_supported(0));
        assert!(is_supported(4 << 20));
    }

    #[test]
    fn ack_body_copy_leaves_the_header_alone() {
        let src = BenchAck {
            seq: 7,
            send_ns: 10,
            recv_ns: 20,
            first_ns: 5,
            count: 3,
            probe: 2,
            ..BenchAck::default()
        };
        let mut dst = BenchAck::default();
        dst.header.seq = 99;
        src.copy_body_into(&mut dst);
        assert_eq!(dst.header.seq, 99);
        assert_eq!((dst.seq, dst.recv_ns, dst.count, dst.probe), (7, 20, 3, 2));
        assert!(dst.validate().is_ok());
        dst.first_ns = 30;
        assert!(dst.validate().is_err());
    }
}
