//! The simulated EtherCAT network: slaves in ring order, each with its
//! state machine, object dictionary, SII image and device model.

pub mod cia402;
pub mod eni_slave;
pub mod esi;
pub mod esm;
pub mod mailbox;
pub mod od;
pub mod pdo_map;
pub mod profiles;
pub mod sdo_info;
pub mod sii_slave;
pub mod slave;

pub use ecmxf_devices::sii;

pub use slave::{Device, Slave};

/// The slaves, in ring position order.
#[derive(Clone, Debug, Default)]
pub struct Network {
    /// Slaves by position.
    pub slaves: Vec<Slave>,
}

impl Network {
    /// A network of these slaves.
    pub fn new(slaves: Vec<Slave>) -> Self {
        Self { slaves }
    }

    /// The demo network: a Neuromeka-CORE-like drive, a TI-like 3-axis drive
    /// and an 8-in/8-out IO slave.
    pub fn demo() -> Self {
        Self::new(vec![
            profiles::neuromeka_core(1001, 1),
            profiles::ti_three_axis(2001, 2),
            profiles::digital_io(3001, 3),
        ])
    }

    /// Slaves that answer (plugged in).
    pub fn present(&self) -> impl Iterator<Item = (usize, &Slave)> {
        self.slaves.iter().enumerate().filter(|(_, s)| s.present)
    }

    /// How many slaves the master reaches: EtherCAT is a line, so an
    /// unplugged slave cuts off every slave after it as well.
    pub fn reachable(&self) -> usize {
        self.slaves.iter().position(|s| !s.present).unwrap_or(self.slaves.len())
    }
}

impl Network {
    /// Pulls a slave out of the ring: it stops answering.
    pub fn unplug(&mut self, i: usize) -> bool {
        self.slaves.get_mut(i).map(|s| s.present = false).is_some()
    }

    /// Plugs a slave back: it powers up again in INIT without a station
    /// address, as a real slave does.
    pub fn replug(&mut self, i: usize) -> bool {
        let Some(s) = self.slaves.get_mut(i) else { return false };
        s.present = true;
        s.esm = esm::Esm::default();
        s.station_address = 0;
        s.since_outputs_ns = 0;
        if let Device::Drive(axes) = &mut s.device {
            for (n, a) in axes.iter_mut().enumerate() {
                *a = cia402::Axis::new(n as u16, a.spec().clone());
            }
        }
        s.sync_registers();
        true
    }
}
