//! One DC cycle of process data (v049 PDO_DATA_FIFO_OP, FIFO and WKC
//! commands; docs/protocol.md §12): take one output frame from the
//! RxFIFO (or repeat the last one and flag a FIFO error when it is empty),
//! let the chip's CiA402 helper write its controlword bits, exchange with
//! every slave, check the working counter, store one input frame in the
//! TxFIFO, raise interrupt flags.

use ecmxf_wire::flags::{ErrorFlags, InterruptFlags};
use ecmxf_wire::payload::cia402::{Cia402Control, Cia402State};

use super::Chip;

/// The controlword bits 0..3 that move an axis one step towards `target`
/// (CiA402 device control commands).
fn helper_command(current: Cia402State, target: Cia402State) -> u16 {
    use Cia402State as S;
    match (current, target) {
        (_, S::SwitchOnDisabled) => 0x00,
        // Quick stop is a command, not a place to walk to: issue it in every
        // state (CiA402 transitions 7, 10, 11; in quick stop active the drive
        // finishes its ramp and, for option codes 0-4, disables itself).
        (_, S::QuickStopActive) => 0x02,
        (S::QuickStopActive, _) => 0x00,
        (S::SwitchOnDisabled, _) => 0x06,
        (S::ReadyToSwitchOn, S::ReadyToSwitchOn) => 0x06,
        (S::ReadyToSwitchOn, _) => 0x07,
        (S::SwitchedOn, S::ReadyToSwitchOn) => 0x06,
        (S::SwitchedOn, S::OperationEnabled) => 0x0F,
        (S::SwitchedOn, _) => 0x07,
        (S::OperationEnabled, S::ReadyToSwitchOn) => 0x06,
        (S::OperationEnabled, S::SwitchedOn) => 0x07,
        (S::OperationEnabled, _) => 0x0F,
        _ => 0x00,
    }
}

impl Chip {
    pub(super) fn run_cycle(&mut self) {
        self.stats.cycles += 1;
        let dt = self.master.cycle_ns;
        let running = self.master.inited && !self.master.exchange_stopped && !self.master.slots.is_empty();

        // A mapping without outputs has no output frames to play, so no
        // RxFIFO to run dry (modelling decision: the manual describes the
        // underrun as repeating the last outputs, and there are none).
        if running && self.fifo.enabled && self.master.rx_size > 0 {
            if self.faults.rx_starved_cycles > 0 {
                self.faults.rx_starved_cycles -= 1;
                self.fifo.rx.clear();
            }
            let repeated = match self.fifo.rx.pop_front() {
                Some(frame) if frame.len() == self.master.outputs.len() => {
                    self.master.outputs = frame;
                    false
                }
                Some(_) => false,
                None => {
                    // Dry RxFIFO: the last outputs repeat.
                    self.fifo.underruns += 1;
                    self.errors |= ErrorFlags::FIFO_ERROR;
                    true
                }
            };
            if let Some(r) = &mut self.fifo.played {
                r.note(self.stats.cycles, &self.master.outputs, repeated);
            }
        }
        if running {
            self.run_helper();
        }

        let mut wkc = 0u16;
        let mut inputs = std::mem::take(&mut self.master.inputs);
        let slots = self.master.slots.clone();
        let reachable = self.net.reachable();
        let mut cycled = vec![false; self.net.slaves.len()];
        for slot in slots.iter().filter(|s| s.slave < reachable) {
            let Some(s) = self.net.slaves.get_mut(slot.slave) else { continue };
            cycled[slot.slave] = true;
            let out = self.master.outputs.get(slot.rx_offset..slot.rx_offset + slot.rx_len);
            // No datagram while exchange is stopped: no working counter.
            let counted = s.cycle(if running { out } else { None }, dt);
            if running {
                wkc += counted;
            }
            if running {
                let n = slot.tx_len.min(s.inputs.len());
                if let Some(dst) = inputs.get_mut(slot.tx_offset..slot.tx_offset + n) {
                    dst.copy_from_slice(&s.inputs[..n]);
                }
            }
        }
        for (i, s) in self.net.slaves.iter_mut().enumerate() {
            if !cycled[i] {
                s.cycle(None, dt);
            }
        }
        self.master.inputs = inputs;
        self.master.wkc = wkc;
        self.collect_emergencies();

        // Checked while process data flows through the FIFO (enabled after
        // OP in the bring-up order): any slave that stops answering for its
        // share, whatever the master asked of it, is a WKC error.
        if running && self.fifo.enabled {
            let expected: u16 = slots.iter().map(|s| u16::from(s.tx_len > 0) + 2 * u16::from(s.rx_len > 0)).sum();
            if wkc != expected {
                self.wkc_errors = self.wkc_errors.wrapping_add(1);
                self.int_flags |= InterruptFlags::WKC_ERROR;
                self.master.wkc_streak = self.master.wkc_streak.saturating_add(1);
                let limit = self.master.wkc_limit;
                if limit != 255 && self.master.wkc_streak > limit {
                    self.master.exchange_stopped = true;
                }
            } else {
                self.master.wkc_streak = 0;
            }
        }
        if running && self.fifo.enabled && !self.faults.tx_stalled {
            let frame = self.master.inputs.clone();
            self.fifo.push_input(frame);
        }
        if running {
            self.int_flags |= InterruptFlags::ETHERCAT_FRAME;
        }
        if self.fifo.tx_high_reached() {
            self.int_flags |= InterruptFlags::TX_FIFO_HIGH;
        }
        if self.fifo.enabled && self.fifo.rx_low_reached() {
            self.int_flags |= InterruptFlags::RX_FIFO_LOW;
        }
    }

    /// The master reads every emergency from the slaves' mailboxes into
    /// the 8-deep history; each also waits as unread mailbox content for
    /// MBX_STAT and RECV_MAILBOX.
    fn collect_emergencies(&mut self) {
        for i in 0..self.net.slaves.len() {
            let found = std::mem::take(&mut self.net.slaves[i].emergencies);
            for e in found {
                self.record_emergency(i as u8, e);
                self.master.unread_mailbox.push((i as u8, e));
            }
        }
    }

    /// The internal CiA402 helper: for each enabled axis, read the
    /// statusword from the last inputs and write controlword bits 0..3 (and
    /// the fault-reset bit 7) into the outputs (v049 402_CONFIG_SET).
    fn run_helper(&mut self) {
        for i in 0..self.helper.len() {
            let Some(mut h) = self.helper[i] else { continue };
            if !h.control.contains(Cia402Control::ENABLE) {
                continue;
            }
            let Some(slot) = self.master.slots.iter().find(|s| s.slave == usize::from(h.slave)).copied() else {
                continue;
            };
            let sw_at = slot.tx_offset + usize::from(h.statusword_offset);
            let cw_at = slot.rx_offset + usize::from(h.controlword_offset);
            let (Some(sw), true) = (self.master.inputs.get(sw_at..sw_at + 2), cw_at + 2 <= self.master.outputs.len())
            else {
                continue;
            };
            let state = Cia402State::from_statusword(u16::from_le_bytes([sw[0], sw[1]]));
            let old = u16::from_le_bytes([self.master.outputs[cw_at], self.master.outputs[cw_at + 1]]);
            let mut cw = (old & !0x008F) | helper_command(state, h.target);
            let resetting = h.control.intersects(Cia402Control::FAULT_RESET | Cia402Control::AUTO_FAULT_RESET);
            if state == Cia402State::Fault && resetting {
                // A rising edge of bit 7 every other cycle.
                h.reset_bit = !h.reset_bit;
                cw = (cw & !0x000F) | if h.reset_bit { 0x80 } else { 0 };
            } else if state != Cia402State::Fault && state != Cia402State::FaultReactionActive {
                h.control.remove(Cia402Control::FAULT_RESET);
                h.reset_bit = false;
            }
            self.master.outputs[cw_at..cw_at + 2].copy_from_slice(&cw.to_le_bytes());
            self.helper[i] = Some(h);
        }
    }
}
