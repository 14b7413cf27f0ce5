//! The cyclic path allocates nothing: with a counting global allocator,
//! the engine thread runs thousands of loop turns (FIFO exchanges, input
//! frames published, client output writes applied, status announced,
//! emergencies asked) and then blocking-slot transactions (SDO reads and
//! writes, slave info), and not one allocation happens on it.
//!
//! Only the engine thread counts, and not while it is inside the simulated
//! chip (the simulator is test equipment; on hardware that time is the SPI
//! transfer): the link below marks both.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use ecmxf_sim::Chip;
use ecmxfd::config::Config;
use ecmxfd::link::sim::SimLink;
use ecmxfd::link::{Link, LinkError};
use ecmxfd::master::Call;
use ecmxfd::master::Master;
use ecmxfd::master::Phase;

/// Counts allocations made on the engine thread while [`WINDOW`] is open.
struct Counting;

static WINDOW: AtomicBool = AtomicBool::new(false);
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    /// Set on the engine thread (the first time it calls the link).
    static ENGINE: Cell<bool> = const { Cell::new(false) };
    /// Set while the engine thread is inside the simulated chip.
    static IN_CHIP: Cell<bool> = const { Cell::new(false) };
}

fn note_allocation() {
    if WINDOW.load(Ordering::Relaxed) && ENGINE.with(Cell::get) && !IN_CHIP.with(Cell::get) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; the
// counting touches only atomics and const-initialised thread-locals, which
// never allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: the caller's contract is passed on as it is.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The simulator as a link, marking the engine thread and the time spent
/// inside the chip.
#[derive(Debug)]
struct Marked(SimLink);

impl Marked {
    fn in_chip<T>(f: impl FnOnce() -> T) -> T {
        ENGINE.with(|e| e.set(true));
        IN_CHIP.with(|c| c.set(true));
        let r = f();
        IN_CHIP.with(|c| c.set(false));
        r
    }
}

impl Link for Marked {
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        Self::in_chip(|| self.0.transfer(tx, rx))
    }
    fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError> {
        Self::in_chip(|| self.0.wait_ready(timeout))
    }
    fn int1_active(&mut self) -> Result<bool, LinkError> {
        Self::in_chip(|| self.0.int1_active())
    }
    fn describe(&self) -> String {
        self.0.describe()
    }
}

/// Blocks until the engine runs (or fails after 20 s).
fn wait_running(m: &Master) {
    let start = Instant::now();
    while m.status().phase != Phase::Running {
        assert!(start.elapsed() < Duration::from_secs(20), "not running: {:?}", m.status());
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn the_cyclic_path_and_transactions_allocate_nothing_on_the_engine_thread() {
    let (link, _sim) = SimLink::new(Chip::new(ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()));
    let master = Arc::new(Master::start(Marked(link), Config::simulator()));
    wait_running(&master);
    // A subscriber, so published frames are distributed (on its own thread).
    let mut inputs = master.subscribe();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    // Warm up: every path runs once before counting (the FIFO plan settles,
    // the fair queue has its line, the first transaction has run).
    rt.block_on(async {
        master.sdo_read(1, 0x1018, 1, false, Call::anonymous(None)).await.unwrap();
        master.sdo_write(1, 0x605A, 0, false, vec![2, 0], Call::anonymous(None)).await.unwrap();
    });
    std::thread::sleep(Duration::from_millis(200));

    let before = master.status();
    WINDOW.store(true, Ordering::SeqCst);
    // The cyclic path: outputs written by a client while the exchange
    // runs, inputs read on the way, for about a second.
    let started = Instant::now();
    let mut k = 0u8;
    while started.elapsed() < Duration::from_millis(1000) {
        k = k.wrapping_add(1);
        master.write_outputs(0, &[k; 4]).unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }
    let cyclic = master.status();
    let cyclic_allocations = ALLOCATIONS.load(Ordering::SeqCst);
    // Transactions: SDO reads and writes, slave information.
    rt.block_on(async {
        for _ in 0..50 {
            master.sdo_read(1, 0x1018, 1, false, Call::anonymous(None)).await.unwrap();
            master.sdo_write(1, 0x605A, 0, false, vec![2, 0], Call::anonymous(None)).await.unwrap();
            master
                .slave_info(2, ecmxf_wire::payload::slave_info::SlaveInfoCode::State, Call::anonymous(None))
                .await
                .unwrap();
        }
    });
    let after = master.status();
    let total = ALLOCATIONS.load(Ordering::SeqCst);
    // The control: an error reply is made on the engine thread (its reason
    // is a String), and the counter sees it.
    rt.block_on(async {
        let e =
            master.slave_info(100, ecmxf_wire::payload::slave_info::SlaveInfoCode::State, Call::anonymous(None)).await;
        assert!(e.is_err(), "slave 100 does not exist: {e:?}");
    });
    WINDOW.store(false, Ordering::SeqCst);
    let control = ALLOCATIONS.load(Ordering::SeqCst) - total;

    let exchanges = cyclic.exchanges - before.exchanges;
    let frames_in = cyclic.input_frames - before.input_frames;
    let frames_out = cyclic.output_frames - before.output_frames;
    let transactions = after.transactions - cyclic.transactions;
    eprintln!(
        "cyclic: {exchanges} exchanges, {frames_in} input and {frames_out} output frames, {cyclic_allocations} allocations; \
         transactions: {transactions}, {} allocations",
        total - cyclic_allocations
    );
    // The test tests something: the engine ran and moved data both ways.
    assert!(exchanges >= 1000, "only {exchanges} exchanges: the engine did not run");
    assert!(frames_in >= 1000 && frames_out >= 1000, "{frames_in} in, {frames_out} out");
    let empty = tokio::sync::broadcast::error::TryRecvError::Empty;
    assert_ne!(inputs.try_recv().err(), Some(empty), "input frames reached the subscriber");
    assert_eq!(transactions, 150);
    assert_eq!(after.phase, Phase::Running);
    assert!(control > 0, "the counter does not see the engine thread's allocations");
    assert_eq!(cyclic_allocations, 0, "allocations on the engine thread in the cyclic path");
    assert_eq!(total - cyclic_allocations, 0, "allocations on the engine thread in transactions");
    master.stop();
}
