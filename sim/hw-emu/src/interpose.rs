//! The libc functions this library puts in front of libc's (LD_PRELOAD):
//! the calls the `spidev` and `gpiocdev` crates, and Rust's std under
//! them, make on device files. A call on a path or descriptor the
//! emulation does not own goes to libc's function untouched (found with
//! `dlsym(RTLD_NEXT)`); so do the emulation's own calls (a per-thread
//! flag), which is how it can use std inside `open` without recursing.
//!
//! `open` and `ioctl` are variadic in C. Rust cannot define variadic
//! functions, so they are defined with the third argument fixed: on the
//! System V x86-64 and the AAPCS64 (Linux) calling conventions a variadic
//! integer or pointer argument travels exactly as a fixed one does.

use std::cell::Cell;
use std::ffi::CStr;
use std::sync::OnceLock;
use std::time::Duration;

use libc::{c_char, c_int, c_uint, c_ulong, c_void, nfds_t, pollfd, size_t, ssize_t, timespec};

use crate::device::{Emu, Errno, emu};

thread_local! {
    static INSIDE: Cell<bool> = const { Cell::new(false) };
}

/// Marks the thread as inside the emulation until dropped.
struct Inside;

impl Inside {
    fn enter() -> Option<Self> {
        if INSIDE.with(Cell::get) {
            return None;
        }
        INSIDE.with(|c| c.set(true));
        Some(Self)
    }
}

impl Drop for Inside {
    fn drop(&mut self) {
        INSIDE.with(|c| c.set(false));
    }
}

/// The emulation, when this call is the program's (not the emulation's
/// own) and `ECMXF_SIM_SOCKET` is set.
fn outside() -> Option<(&'static Emu, Inside)> {
    let inside = Inside::enter()?;
    Some((emu()?, inside))
}

fn set_errno(e: Errno) {
    // SAFETY: errno is this thread's.
    unsafe { *libc::__errno_location() = e };
}

fn errno_or<T: From<i8>>(r: Result<T, Errno>) -> T {
    r.unwrap_or_else(|e| {
        set_errno(e);
        T::from(-1)
    })
}

/// libc's own `name`, as a function pointer of type `F`.
macro_rules! real {
    ($name:literal: $ty:ty) => {{
        static ADDRESS: OnceLock<usize> = OnceLock::new();
        let address = *ADDRESS.get_or_init(|| {
            // SAFETY: a NUL-terminated name; RTLD_NEXT finds the definition
            // after this library's, libc's.
            unsafe { libc::dlsym(libc::RTLD_NEXT, concat!($name, "\0").as_ptr() as *const c_char) as usize }
        });
        assert!(address != 0, concat!("ecmxf-hw-emu: libc has no ", $name));
        // SAFETY: the address of libc's function of this C signature.
        unsafe { std::mem::transmute::<usize, $ty>(address) }
    }};
}

/// Opens `path` if it is an emulated node; `None` to let libc open it.
///
/// # Safety
/// `path` is a C string or null.
unsafe fn try_open(path: *const c_char, flags: c_int) -> Option<c_int> {
    if path.is_null() {
        return None;
    }
    let (emu, _inside) = outside()?;
    // SAFETY: the caller's C string.
    let text = unsafe { CStr::from_ptr(path) }.to_str().ok()?;
    let node = emu.config.node(text)?;
    Some(errno_or(emu.open(text, node, flags)))
}

type OpenFn = unsafe extern "C" fn(*const c_char, c_int, c_uint) -> c_int;
type OpenAtFn = unsafe extern "C" fn(c_int, *const c_char, c_int, c_uint) -> c_int;

/// `open(2)`.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn open(path: *const c_char, flags: c_int, mode: c_uint) -> c_int {
    // SAFETY: the caller's C string.
    if let Some(r) = unsafe { try_open(path, flags) } {
        return r;
    }
    let f = real!("open": OpenFn);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(path, flags, mode) }
}

/// `open64`, which Rust's `File::open` calls.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn open64(path: *const c_char, flags: c_int, mode: c_uint) -> c_int {
    // SAFETY: the caller's C string.
    if let Some(r) = unsafe { try_open(path, flags) } {
        return r;
    }
    let f = real!("open64": OpenFn);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(path, flags, mode) }
}

/// `openat(2)`: absolute paths only are emulated (the directory is then
/// ignored, as the kernel ignores it).
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn openat(dir: c_int, path: *const c_char, flags: c_int, mode: c_uint) -> c_int {
    // SAFETY: the caller's C string.
    if let Some(r) = unsafe { try_open(path, flags) } {
        return r;
    }
    let f = real!("openat": OpenAtFn);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(dir, path, flags, mode) }
}

/// `openat64`.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn openat64(dir: c_int, path: *const c_char, flags: c_int, mode: c_uint) -> c_int {
    // SAFETY: the caller's C string.
    if let Some(r) = unsafe { try_open(path, flags) } {
        return r;
    }
    let f = real!("openat64": OpenAtFn);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(dir, path, flags, mode) }
}

/// `__open_2`, the fortified `open` C programs call.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn __open_2(path: *const c_char, flags: c_int) -> c_int {
    type F = unsafe extern "C" fn(*const c_char, c_int) -> c_int;
    // SAFETY: the caller's C string.
    if let Some(r) = unsafe { try_open(path, flags) } {
        return r;
    }
    let f = real!("__open_2": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(path, flags) }
}

/// `__open64_2`.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn __open64_2(path: *const c_char, flags: c_int) -> c_int {
    type F = unsafe extern "C" fn(*const c_char, c_int) -> c_int;
    // SAFETY: the caller's C string.
    if let Some(r) = unsafe { try_open(path, flags) } {
        return r;
    }
    let f = real!("__open64_2": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(path, flags) }
}

/// `ioctl(2)`.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ioctl(fd: c_int, request: c_ulong, arg: *mut c_void) -> c_int {
    type F = unsafe extern "C" fn(c_int, c_ulong, *mut c_void) -> c_int;
    if let Some((emu, _inside)) = outside().filter(|(e, _)| e.owns(fd)) {
        #[allow(clippy::useless_conversion, reason = "c_ulong is u32 on 32-bit targets")]
        let request = u64::from(request);
        // SAFETY: the caller's argument, as the request number says.
        return errno_or(unsafe { emu.ioctl(fd, request, arg) });
    }
    let f = real!("ioctl": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(fd, request, arg) }
}

/// `read(2)`: edge events from a line request.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn read(fd: c_int, buf: *mut c_void, count: size_t) -> ssize_t {
    type F = unsafe extern "C" fn(c_int, *mut c_void, size_t) -> ssize_t;
    if let Some((emu, _inside)) = outside().filter(|(e, _)| e.owns(fd)) {
        // SAFETY: the caller's buffer of `count` bytes.
        return errno_or(unsafe { emu.read(fd, buf, count) });
    }
    let f = real!("read": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(fd, buf, count) }
}

/// Polls emulated files only (`None` when any descriptor is another file:
/// libc polls those, and emulated ones then never look readable).
///
/// # Safety
/// `fds` holds `n` entries.
unsafe fn try_poll(fds: *mut pollfd, n: nfds_t, timeout: Option<Duration>) -> Option<c_int> {
    if fds.is_null() || n == 0 {
        return None;
    }
    let (emu, _inside) = outside()?;
    // SAFETY: the caller's array of `n` entries.
    let fds = unsafe { std::slice::from_raw_parts_mut(fds, n as usize) };
    if !fds.iter().all(|p| emu.owns(p.fd)) {
        return None;
    }
    emu.polled();
    let deadline = timeout.map(|t| std::time::Instant::now() + t);
    loop {
        let one = fds.len() == 1;
        let mut ready = 0;
        for p in fds.iter_mut() {
            let wait = if one { timeout } else { Some(Duration::ZERO) };
            p.revents = match emu.wait_events(p.fd, wait) {
                Ok(true) if p.events & libc::POLLIN != 0 => libc::POLLIN,
                Ok(_) => 0,
                Err(_) => libc::POLLERR,
            };
            ready += c_int::from(p.revents != 0);
        }
        let expired = deadline.is_some_and(|d| std::time::Instant::now() >= d);
        if ready > 0 || one || expired {
            return Some(ready);
        }
        std::thread::sleep(Duration::from_micros(100));
    }
}

/// `ppoll(2)`, which gpiocdev waits for edge events with. The signal mask
/// is not applied to emulated waits.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn ppoll(fds: *mut pollfd, n: nfds_t, timeout: *const timespec, mask: *const c_void) -> c_int {
    type F = unsafe extern "C" fn(*mut pollfd, nfds_t, *const timespec, *const c_void) -> c_int;
    let wait = if timeout.is_null() {
        None
    } else {
        // SAFETY: the caller's timespec.
        let t = unsafe { *timeout };
        Some(Duration::new(t.tv_sec.max(0) as u64, t.tv_nsec.clamp(0, 999_999_999) as u32))
    };
    // SAFETY: the caller's array.
    if let Some(r) = unsafe { try_poll(fds, n, wait) } {
        return r;
    }
    let f = real!("ppoll": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(fds, n, timeout, mask) }
}

/// `poll(2)`.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn poll(fds: *mut pollfd, n: nfds_t, timeout_ms: c_int) -> c_int {
    type F = unsafe extern "C" fn(*mut pollfd, nfds_t, c_int) -> c_int;
    let wait = (timeout_ms >= 0).then(|| Duration::from_millis(timeout_ms as u64));
    // SAFETY: the caller's array.
    if let Some(r) = unsafe { try_poll(fds, n, wait) } {
        return r;
    }
    let f = real!("poll": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(fds, n, timeout_ms) }
}

/// `close(2)`: an emulated file is forgotten, then its descriptor (the
/// connection to the simulator) closed.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn close(fd: c_int) -> c_int {
    type F = unsafe extern "C" fn(c_int) -> c_int;
    if let Some((emu, _inside)) = outside() {
        emu.close(fd);
    }
    let f = real!("close": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(fd) }
}

/// `realpath(3)`, which gpiocdev resolves the chip's path with: an
/// emulated node is its own real path.
///
/// # Safety
/// As libc's.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn realpath(path: *const c_char, resolved: *mut c_char) -> *mut c_char {
    type F = unsafe extern "C" fn(*const c_char, *mut c_char) -> *mut c_char;
    let emulated = !path.is_null()
        && outside().is_some_and(|(emu, _inside)| {
            // SAFETY: the caller's C string.
            let text = unsafe { CStr::from_ptr(path) };
            text.to_str().is_ok_and(|t| emu.config.node(t).is_some())
        });
    if emulated {
        // SAFETY: `path` is a C string; a null `resolved` asks for a
        // malloc'd copy, else it has room for PATH_MAX bytes.
        return unsafe {
            if resolved.is_null() { libc::strdup(path) } else { libc::strncpy(resolved, path, libc::PATH_MAX as usize) }
        };
    }
    let f = real!("realpath": F);
    // SAFETY: libc's function with the caller's arguments.
    unsafe { f(path, resolved) }
}

/// Writes the counters when the program exits (`exit` runs the
/// `.fini_array` functions).
extern "C" fn at_exit() {
    if let Some((emu, _inside)) = outside() {
        emu.write_stats();
    }
}

#[used]
#[unsafe(link_section = ".fini_array")]
static AT_EXIT: extern "C" fn() = at_exit;
