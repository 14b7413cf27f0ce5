//! The preload library in a process of its own, driven with raw system
//! calls the way a C program would make them: the errors and answers the
//! kernel gives. The test re-runs its own executable with LD_PRELOAD set
//! (a library preloaded into an already running process takes no effect).

use std::ffi::CString;
use std::os::unix::net::UnixListener;
use std::path::PathBuf;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use ecmxf_sim::server::Server;
use ecmxf_sim::{Chip, ChipConfig, Network};

/// target/<profile>/deps/libecmxf_hw_emu.so: cargo builds it there, fresh,
/// before this test (the package's lib is a cdylib and an rlib).
fn library() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let lib = exe.parent().unwrap().join("libecmxf_hw_emu.so");
    assert!(lib.exists(), "{} not built", lib.display());
    lib
}

fn errno() -> i32 {
    std::io::Error::last_os_error().raw_os_error().unwrap_or(0)
}

fn open(path: &str, flags: i32) -> Result<i32, i32> {
    let c = CString::new(path).unwrap();
    // SAFETY: a C string.
    let fd = unsafe { libc::open(c.as_ptr(), flags) };
    if fd < 0 { Err(errno()) } else { Ok(fd) }
}

/// `_IOC(dir, type, nr, size)`.
const fn ioc(dir: u64, ty: u8, nr: u8, size: usize) -> u64 {
    (dir << 30) | ((size as u64) << 16) | ((ty as u64) << 8) | nr as u64
}

#[repr(C)]
struct LineRequest {
    offsets: [u32; 64],
    consumer: [u8; 32],
    config_flags: u64,
    num_attrs: u32,
    config_padding: [u32; 5],
    attrs: [[u64; 3]; 10],
    num_lines: u32,
    event_buffer_size: u32,
    padding: [u32; 5],
    fd: i32,
}

fn request(chip: i32, offset: u32, flags: u64) -> Result<i32, i32> {
    let mut r = LineRequest {
        offsets: [0; 64],
        consumer: [0; 32],
        config_flags: flags,
        num_attrs: 0,
        config_padding: [0; 5],
        attrs: [[0; 3]; 10],
        num_lines: 1,
        event_buffer_size: 0,
        padding: [0; 5],
        fd: -1,
    };
    r.offsets[0] = offset;
    r.consumer[..4].copy_from_slice(b"test");
    // SAFETY: GPIO_V2_GET_LINE_IOCTL with a gpio_v2_line_request.
    let rc = unsafe { libc::ioctl(chip, ioc(3, 0xB4, 0x07, 592), &mut r) };
    if rc < 0 { Err(errno()) } else { Ok(r.fd) }
}

/// The checks, in the child with the library preloaded.
fn child() {
    assert_eq!(open("/dev/spidev1.0", libc::O_RDWR), Err(libc::ENOENT), "a node not emulated");
    assert_eq!(open("/dev/spidev0.1", libc::O_RDWR), Err(libc::EACCES), "ECMXF_EMU_DENY");
    let spi = open("/dev/spidev0.0", libc::O_RDWR).expect("spidev");
    let mut mode: u32 = 3;
    // SAFETY: SPI_IOC_WR_MODE32 with a u32.
    assert_eq!(unsafe { libc::ioctl(spi, ioc(1, b'k', 5, 4), &mode) }, 0);
    mode = 0;
    // SAFETY: SPI_IOC_RD_MODE32 with a u32.
    assert_eq!(unsafe { libc::ioctl(spi, ioc(2, b'k', 5, 4), &mut mode) }, 0);
    assert_eq!(mode, 3);
    let bits: u8 = 9;
    // SAFETY: SPI_IOC_WR_BITS_PER_WORD with a u8.
    assert_eq!(unsafe { libc::ioctl(spi, ioc(1, b'k', 3, 1), &bits) }, -1);
    assert_eq!(errno(), libc::EINVAL, "a word size the controller does not take");
    // SAFETY: an ioctl spidev does not know.
    assert_eq!(unsafe { libc::ioctl(spi, ioc(1, b'k', 9, 4), &mode) }, -1);
    assert_eq!(errno(), libc::ENOTTY);
    // One spi_ioc_transfer of 5000 bytes (above spidev's bufsiz), no buffers.
    let t = [0u64, 0, 5000, 0];
    // SAFETY: one spi_ioc_transfer (32 bytes) with null buffers.
    assert_eq!(unsafe { libc::ioctl(spi, ioc(1, b'k', 0, 32), t.as_ptr()) }, -1);
    assert_eq!(errno(), libc::EMSGSIZE);
    // SAFETY: our descriptor.
    assert_eq!(unsafe { libc::close(spi) }, 0);

    let chip = open("/dev/gpiochip0", libc::O_RDONLY | libc::O_CLOEXEC).expect("gpiochip");
    let mut info = [0u8; 68];
    // SAFETY: GPIO_GET_CHIPINFO_IOCTL with a 68-byte gpiochip_info.
    assert_eq!(unsafe { libc::ioctl(chip, ioc(2, 0xB4, 0x01, 68), info.as_mut_ptr()) }, 0);
    assert!(info.starts_with(b"gpiochip0\0"));
    assert_eq!(u32::from_ne_bytes(info[64..68].try_into().unwrap()), 58);
    const INPUT_BOTH_EDGES: u64 = (1 << 2) | (1 << 4) | (1 << 5);
    assert_eq!(request(chip, 24, 1 << 4), Err(libc::EINVAL), "edges without input");
    assert_eq!(request(chip, 58, INPUT_BOTH_EDGES), Err(libc::EINVAL), "no such line");
    let int0 = request(chip, 24, INPUT_BOTH_EDGES).expect("INT0");
    assert_eq!(request(chip, 24, INPUT_BOTH_EDGES), Err(libc::EBUSY), "held by the first request");
    let mut values = [0u64, 1];
    // SAFETY: GPIO_V2_LINE_GET_VALUES_IOCTL with gpio_v2_line_values.
    assert_eq!(unsafe { libc::ioctl(int0, ioc(3, 0xB4, 0x0E, 16), values.as_mut_ptr()) }, 0);
    assert_eq!(values[0], 1, "INT0 says ready after power-up (active high)");
    let mut small = [0u8; 16];
    // SAFETY: a buffer smaller than one event.
    assert_eq!(unsafe { libc::read(int0, small.as_mut_ptr().cast(), small.len()) }, -1);
    assert_eq!(errno(), libc::EINVAL);
    let mut p = libc::pollfd { fd: int0, events: libc::POLLIN, revents: 0 };
    // SAFETY: one pollfd; nothing clocked, so no edge in 20 ms.
    assert_eq!(unsafe { libc::poll(&mut p, 1, 20) }, 0);
    // SAFETY: our descriptor; closing frees the line.
    assert_eq!(unsafe { libc::close(int0) }, 0);
    let again = request(chip, 24, INPUT_BOTH_EDGES).expect("free again once closed");
    // SAFETY: our descriptors.
    unsafe {
        libc::close(again);
        libc::close(chip);
    }
}

#[test]
fn the_emulated_devices_answer_as_the_kernel_does() {
    if std::env::var_os("ECMXF_HW_EMU_CHILD").is_some() {
        child();
        return;
    }
    let dir = std::env::temp_dir().join(format!("ecmxf-hw-emu-abi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let socket = dir.join("sim.sock");
    let listener = UnixListener::bind(&socket).unwrap();
    let chip = Chip::new(Network::demo(), ChipConfig::default());
    let server = Arc::new(Server::new(chip));
    let stop = Arc::new(AtomicBool::new(false));
    let serving = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || server.serve(listener, stop))
    };
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "the_emulated_devices_answer_as_the_kernel_does", "--nocapture"])
        .env("ECMXF_HW_EMU_CHILD", "1")
        .env("LD_PRELOAD", library())
        .env("ECMXF_SIM_SOCKET", &socket)
        .env("ECMXF_EMU_SPIDEV", "/dev/spidev0.0,/dev/spidev0.1")
        .env("ECMXF_EMU_DENY", "/dev/spidev0.1")
        .output()
        .unwrap();
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let _ = serving.join();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        out.status.success(),
        "child failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
