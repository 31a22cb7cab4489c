//! A tick allocates nothing: a counting global allocator armed only around the core's calls on this thread.

mod support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use kinloop_client::core::{ConstraintMode, ModelForm};
use kinloop_client::device::HapticDevice;
use support::ClosedLoop;

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if ARMED.with(Cell::get) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if ARMED.with(Cell::get) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if ARMED.with(Cell::get) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn counted<T>(f: impl FnOnce() -> T) -> (T, u64) {
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let out = f();
    ARMED.with(|a| a.set(false));
    (out, COUNT.with(Cell::get))
}

#[test]
fn a_tick_and_a_snapshot_intake_allocate_nothing() {
    for (mode, form) in [
        (ConstraintMode::Stiffness, ModelForm::Op),
        (ConstraintMode::Impedance, ModelForm::Op),
        (ConstraintMode::Stiffness, ModelForm::Config),
    ] {
        let mut l = ClosedLoop::paper(mode, form);
        for _ in 0..50 {
            l.tick();
        }
        let mut total = 0;
        for _ in 0..1200 {
            // The fixture's VE allocates (snapshots are Vecs on the wire); only the core's calls are counted.
            let snapshot = l.ve.snapshot();
            let now = l.now;
            let device = l.rig.read(now).expect("reads");
            let ((), allocations) = counted(|| {
                l.core.handle_snapshot(now, &snapshot).expect("valid");
                let out = l.core.tick(now, &device);
                std::hint::black_box(out.command);
                std::hint::black_box(out.uplink.map(|u| u.seq));
            });
            total += allocations;
            l.ve.step();
            l.now += std::time::Duration::from_millis(1);
        }
        assert_eq!(total, 0, "{mode:?}/{form:?}: ticks allocated {total} times");
    }
}
