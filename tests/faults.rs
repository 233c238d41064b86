//! Faults from outside the stack: a rogue publisher writing random bytes into every topic.

use mole_integration_tests::*;
use mole_runtime::{ClockMode, CommonArgs, Context, Publisher};
use mole_types::{Message, topics};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// xorshift64*: reproducible garbage.
struct Garbage(u64);

impl Garbage {
    fn fill(&mut self, bytes: &mut [u8]) {
        for chunk in bytes.chunks_mut(8) {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let word = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D).to_le_bytes();
            chunk.copy_from_slice(&word[..chunk.len()]);
        }
    }
}

fn spray<M: Message>(publisher: &mut Publisher<M>, garbage: &mut Garbage, count: usize) {
    for _ in 0..count {
        // Tick 0: the steps are long past, so the garbage competes on content, not on time.
        let _ = publisher.publish(0, 0, |m| garbage.fill(bytemuck::bytes_of_mut(m)));
    }
}

#[test]
fn random_bytes_on_every_topic_crash_nothing_and_are_counted() {
    let _serial = serial();
    let stack = Stack::start("rogue", &["--mode", "realtime", "--ticks", "700"]);
    stack.wait_for_log("world", "ready", Duration::from_secs(60));
    let args = CommonArgs {
        namespace: stack.namespace.clone(),
        mode: ClockMode::Realtime,
        rate_hz: 100.0,
        seed: None,
    };
    let rogue = Context::with_shutdown_flag("rogue", &args, Arc::new(AtomicBool::new(false)))
        .expect("rogue context");
    let mut garbage = Garbage(0x9E37_79B9_7F4A_7C15);
    let n = 40;
    spray(
        &mut rogue.publisher(topics::WORLD_TRUTH).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::SENSING_SCAN).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::SENSING_TACTILE).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::SENSING_ODOM).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::SENSING_BEACONS).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::SENSING_FIX).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::LOCALIZATION_POSE).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::MAPPING_GRID).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::MAPPING_CONTACT).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::PLANNING_CMD).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::PLANNING_STATUS).unwrap(),
        &mut garbage,
        n,
    );
    spray(
        &mut rogue.publisher(topics::STACK_STATS).unwrap(),
        &mut garbage,
        n,
    );
    drop(rogue);

    let out = stack.out.clone();
    let keep = out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, Duration::from_secs(240));
    let logs = logs(&keep);
    let summary = summary(&keep);
    let _ = std::fs::remove_dir_all(&keep);
    assert!(output.status.success(), "{logs}");
    assert_eq!(summary["exit_reason"], "ticks", "{summary:#}");
    for (role, restarts) in summary["restarts"].as_object().expect("restarts") {
        assert_eq!(restarts, 0, "{role} crashed:\n{logs}");
    }
    let invalid: u64 = summary["topics"]
        .as_object()
        .expect("topics")
        .values()
        .filter_map(|t| t["invalid"].as_u64())
        .sum();
    assert!(
        invalid > 0,
        "the garbage was refused and counted: {summary:#}"
    );
    assert!(
        summary["topics"]["planning/cmd"]["invalid"]
            .as_u64()
            .is_some_and(|n| n > 0),
        "{summary:#}"
    );
}
