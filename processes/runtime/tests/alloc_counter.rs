//! The counting allocator really counts (so a zero in the processes' checks means something).

use mole_runtime::{CountingAllocator, allocations_during};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

#[test]
fn allocations_are_counted_and_plain_arithmetic_is_not() {
    let n = allocations_during(|| {
        let v: Vec<u64> = (0..100).collect();
        std::hint::black_box(v);
    });
    assert!(n >= 1, "{n}");
    let mut x = 1u64;
    let n = allocations_during(|| {
        for i in 0..1000 {
            x = x.wrapping_mul(31).wrapping_add(i);
        }
    });
    std::hint::black_box(x);
    assert_eq!(n, 0);
}
