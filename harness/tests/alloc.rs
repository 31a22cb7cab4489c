//! A tick allocates nothing: a counting global allocator armed only around the core's calls on this thread.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use std::time::Duration;

use kinloop_client::core::{ConstraintMode, HapticCore, ModelForm, TickOutput};
use kinloop_client::device::DeviceState;
use kinloop_harness::{CoreHooks, Session, SessionPlan};
use kinloop_linkage::math::space::Planar;
use kinloop_protocol::Snapshot;

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

/// Counts what the core's snapshot intake and tick allocate; the session around them (codec, links, VE)
/// allocates as it likes.
#[derive(Default)]
struct CountCore {
    allocations: u64,
}

impl CoreHooks<Planar> for CountCore {
    fn snapshot(&mut self, _who: usize, core: &mut HapticCore<Planar>, now: Duration, snapshot: &mut Snapshot) {
        let (result, allocations) = counted(|| core.handle_snapshot(now, snapshot).map(|_| ()));
        result.expect("valid");
        self.allocations += allocations;
    }

    fn tick<'c>(
        &mut self,
        _who: usize,
        core: &'c mut HapticCore<Planar>,
        now: Duration,
        device: &DeviceState<Planar>,
    ) -> TickOutput<'c, Planar> {
        let (out, allocations) = counted(|| {
            let out = core.tick(now, device);
            std::hint::black_box(out.command);
            std::hint::black_box(out.uplink.map(|u| u.seq));
            out
        });
        self.allocations += allocations;
        out
    }
}

#[test]
fn a_tick_and_a_snapshot_intake_allocate_nothing() {
    for (mode, form) in [
        (ConstraintMode::Stiffness, ModelForm::Op),
        (ConstraintMode::Impedance, ModelForm::Op),
        (ConstraintMode::Stiffness, ModelForm::Config),
    ] {
        let plan = SessionPlan::paper_manipulation(mode, form).expect("the paper's plan");
        let mut session = Session::<Planar>::new(&plan).expect("the session");
        let mut warm_up = CountCore::default();
        session.run_until_with(Duration::from_millis(50), &mut warm_up).expect("steps");
        let mut count = CountCore::default();
        session.run_until_with(Duration::from_millis(1250), &mut count).expect("steps");
        assert!(session.core(0).expect("joined").stats().snapshots_accepted > 1000, "{mode:?}/{form:?}");
        let total = count.allocations;
        assert_eq!(total, 0, "{mode:?}/{form:?}: ticks allocated {total} times");
    }
}
