//! A VE tick and the snapshots it builds allocate nothing once the users have joined: counted by a global
//! allocator that counts the calls made on the measuring thread.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::time::Duration;

use kinloop_linkage::{math::space::Planar, math::space::Space, model::scene::Scene, model::Model};
use kinloop_protocol::{codec, DeviceCaps, LocalModelForm, Role};
use kinloop_server::core::{JoinRequest, UplinkSample, VeConfig, VeCore};

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static CALLS: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    // `try_with`: the thread-locals may be gone while a thread exits.
    if COUNTING.try_with(|c| c.get()).unwrap_or(false) {
        let _ = CALLS.try_with(|c| c.set(c.get() + 1));
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note();
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Allocator calls (allocations, frees, reallocations) made by `f` on this thread.
fn allocator_calls(f: impl FnOnce()) -> u64 {
    CALLS.with(|c| c.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    CALLS.with(|c| c.get())
}

fn device(k: usize) -> DeviceCaps {
    DeviceCaps { max_force_n: 50.0, continuous_force_n: 25.0, max_torque_nm: 5.0, ..DeviceCaps::generous("d", k) }
}

/// Joins `forms.len()` users (manipulators and one observer), then counts the allocator calls of `ticks`
/// ticks in which every user sends an uplink and every snapshot is polled and encoded.
fn calls_per_run<S: Space>(model: Model<S>, forms: &[LocalModelForm], passivity: bool, ticks: usize) -> u64 {
    let mut config = VeConfig::paper();
    config.passivity = passivity;
    let op = model.ops[0].name.clone();
    let mut core = VeCore::new(model, config).unwrap();
    let users: Vec<u32> = forms
        .iter()
        .enumerate()
        .map(|(i, form)| {
            let role = if i == 1 { Role::Observer } else { Role::Manipulator };
            let request = JoinRequest {
                name: format!("u{i}"),
                role,
                op: op.clone(),
                form: *form,
                device: Some(device(S::DIM)),
                mapping: Default::default(),
            };
            core.join(Duration::ZERO, request).unwrap().user_id
        })
        .collect();
    let mut samples: Vec<Option<UplinkSample>> = vec![None; users.len()];
    let mut encoded = Vec::with_capacity(codec::limits::MAX_DATAGRAM_MESSAGE_BYTES);
    let mut seq = 0;
    let mut tick = |core: &mut VeCore<S>| {
        let now = core.poll_timeout();
        seq += 1;
        for (i, user) in users.iter().enumerate() {
            if let Some(sample) = samples[i].as_mut() {
                sample.seq = seq;
                sample.hand_wrench[0] = if i % 2 == 0 { -0.5 } else { 0.4 };
                core.handle_uplink_sample(now, *user, sample).unwrap();
            }
        }
        core.handle_timeout(now);
        while let Some(pending) = core.poll_snapshot() {
            codec::encode_datagram_into(pending.datagram(), &mut encoded).unwrap();
            let s = pending.snapshot();
            let i = users.iter().position(|u| *u == s.user_id).unwrap();
            let sample = samples[i].get_or_insert(UplinkSample::zeroed(s.op_twist.len() as u8, s.op_pose.len() as u8));
            sample.model_pose[..s.op_pose.len()].copy_from_slice(&s.op_pose);
            // Each uplink answers the newest snapshot, so the round-trip estimate is kept up too.
            sample.last_snapshot_seq = s.seq;
            sample.model_twist[..s.op_twist.len()].copy_from_slice(&s.op_twist);
        }
        while core.poll_event().is_some() {}
    };
    // Warm up: first snapshots size the lists, first uplinks start the fades.
    for _ in 0..300 {
        tick(&mut core);
    }
    let calls = allocator_calls(|| {
        for _ in 0..ticks {
            tick(&mut core);
        }
    });
    assert_eq!(core.metrics().state_restores, 0);
    assert!(core.metrics().snapshots_built > 0);
    calls
}

fn scene(name: &str) -> Scene {
    kinloop_linkage::model::builtin::scene(name).unwrap().unwrap()
}

#[test]
fn ticks_and_snapshots_allocate_nothing_for_a_fixed_set_of_users() {
    use LocalModelForm::{ConfigSpace, OpSpace};
    // The counter does count.
    assert!(allocator_calls(|| drop(std::hint::black_box(vec![1u8; 10]))) >= 2);
    let testbed = Model::<Planar>::compile(&scene("paper-testbed"), "paper-testbed").unwrap();
    assert_eq!(calls_per_run(testbed.clone(), &[OpSpace, OpSpace, ConfigSpace, OpSpace], false, 500), 0);
    assert_eq!(calls_per_run(testbed, &[OpSpace, OpSpace], true, 500), 0, "with passivity");
    // A scene with an obstacle: contact terms in every snapshot.
    let slider = Model::<Planar>::compile(&scene("slider-crank"), "slider-crank").unwrap();
    assert_eq!(calls_per_run(slider, &[OpSpace, OpSpace, ConfigSpace], false, 500), 0, "with contacts");
    let spatial =
        Model::<kinloop_linkage::math::space::Spatial>::compile(&scene("spherical-four-bar"), "spherical").unwrap();
    assert_eq!(calls_per_run(spatial, &[OpSpace, OpSpace], false, 500), 0, "spatial");
}

/// The VE thread's side of the web view (`--view`): copying each snapshot's directions and writing a frame
/// into the view's ring, whether the ring takes it or is full, allocates nothing.
#[test]
fn the_view_tap_allocates_nothing_per_tick() {
    let model = Model::<Planar>::compile(&scene("paper-testbed"), "paper-testbed").unwrap();
    let n = model.nv();
    let mut core = VeCore::new(model, VeConfig::paper()).unwrap();
    for (i, role) in [Role::Manipulator, Role::Observer].into_iter().enumerate() {
        let request = JoinRequest {
            name: format!("u{i}"),
            role,
            op: "link2".into(),
            form: LocalModelForm::OpSpace,
            device: Some(device(3)),
            mapping: Default::default(),
        };
        core.join(Duration::ZERO, request).unwrap();
    }
    // A frame every tick: the ring (8 frames) fills during the count, so both paths run.
    let (mut tap, _reader) = kinloop_server::view::tap::<Planar>(n, 4, 1000.0, 1000.0);
    let stats = kinloop_server::driver::VeLoopStats::default();
    let tick = |core: &mut VeCore<Planar>, tap: &mut kinloop_server::view::ViewTap| {
        core.handle_timeout(core.poll_timeout());
        while let Some(pending) = core.poll_snapshot() {
            tap.note_snapshot(pending.snapshot());
        }
        while core.poll_event().is_some() {}
        tap.after_tick(core, &stats);
    };
    tick(&mut core, &mut tap);
    let calls = allocator_calls(|| {
        for _ in 0..200 {
            tick(&mut core, &mut tap);
        }
    });
    assert_eq!(calls, 0);
    assert!(tap.published >= 8 && tap.dropped > 0, "published {}, dropped {}", tap.published, tap.dropped);
}

/// The rehearsal the VE loop runs before each deadline (`kinloop_server::driver::rehearsal`), and the
/// prefetch beside it, allocate nothing once its user holds the linkage.
#[test]
fn the_rehearsal_before_a_deadline_allocates_nothing() {
    let model = Model::<Planar>::compile(&scene("paper-testbed"), "paper-testbed").unwrap();
    let core = VeCore::new(model.clone(), VeConfig::paper()).unwrap();
    let mut rehearsal = kinloop_server::driver::rehearsal::Rehearsal::new(&model, &VeConfig::paper()).unwrap();
    for _ in 0..10 {
        rehearsal.rehearse();
    }
    let calls = allocator_calls(|| {
        for _ in 0..200 {
            rehearsal.rehearse();
            core.prefetch();
        }
    });
    assert_eq!(calls, 0);
}
