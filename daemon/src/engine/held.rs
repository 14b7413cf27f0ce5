//! The outputs the lease holders wrote, kept per slave across recoveries.
//!
//! A recovery may bring the network up with another shape: a slave
//! unplugged during the fault is missing from the next bring-up (the image
//! shrinks and shifts) and back in the one after. Kept as one image, the
//! outputs were lost at the first change and the slaves restarted with
//! zeros. Kept per slave (identity and which of its kind, in ring order),
//! every slave gets back what was written for it, whatever else changed;
//! a slave never seen before starts at zero.

use super::layout::SlaveSummary;

/// Which slave: identity, and the how-manieth of that identity on the ring.
type Key = (u32, u32, u32, usize);

fn keys(slaves: &[SlaveSummary]) -> impl Iterator<Item = (Key, &SlaveSummary)> {
    slaves.iter().enumerate().map(|(i, s)| {
        let same_before = slaves[..i]
            .iter()
            .filter(|o| (o.vendor_id, o.product_code, o.revision) == (s.vendor_id, s.product_code, s.revision))
            .count();
        ((s.vendor_id, s.product_code, s.revision, same_before), s)
    })
}

/// Output bytes per slave (allocated at recovery, never on the cycle).
#[derive(Debug, Default)]
pub(crate) struct HeldOutputs {
    slaves: Vec<(Key, Vec<u8>)>,
}

impl HeldOutputs {
    /// Takes the image a run ended with, for the slaves of that run; the
    /// bytes of slaves not in it are kept.
    pub(crate) fn keep(&mut self, slaves: &[SlaveSummary], image: &[u8]) {
        for (key, s) in keys(slaves) {
            let Some(bytes) = image.get(s.rx_offset..s.rx_offset + s.rx_bytes) else { continue };
            match self.slaves.iter_mut().find(|(k, _)| *k == key) {
                Some((_, b)) => *b = bytes.to_vec(),
                None => self.slaves.push((key, bytes.to_vec())),
            }
        }
    }

    /// Forgets everything (policy "zero": the next run starts from zeros).
    pub(crate) fn clear(&mut self) {
        self.slaves.clear();
    }

    /// The output image for a network of `slaves` with `rx_size` output
    /// bytes: each slave's kept bytes where they still fit, zeros elsewhere.
    pub(crate) fn image_for(&self, slaves: &[SlaveSummary], rx_size: usize) -> Vec<u8> {
        let mut image = vec![0u8; rx_size];
        for (key, s) in keys(slaves) {
            let kept = self.slaves.iter().find(|(k, _)| *k == key).map(|(_, b)| b);
            if let (Some(kept), Some(dst)) = (kept, image.get_mut(s.rx_offset..s.rx_offset + s.rx_bytes)) {
                if kept.len() == dst.len() {
                    dst.copy_from_slice(kept);
                }
            }
        }
        image
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slave(product: u32, rx_offset: usize, rx_bytes: usize) -> SlaveSummary {
        SlaveSummary { vendor_id: 1, product_code: product, rx_offset, rx_bytes, ..SlaveSummary::default() }
    }

    #[test]
    fn a_slave_missing_for_one_run_gets_its_outputs_back() {
        let mut held = HeldOutputs::default();
        let full = [slave(10, 0, 2), slave(20, 2, 1), slave(30, 3, 2)];
        held.keep(&full, &[1, 2, 3, 4, 5]);
        // The middle slave is unplugged: the image shrinks and shifts.
        let short = [slave(10, 0, 2), slave(30, 2, 2)];
        assert_eq!(held.image_for(&short, 4), [1, 2, 4, 5]);
        held.keep(&short, &[1, 2, 4, 5]);
        // It is back.
        assert_eq!(held.image_for(&full, 5), [1, 2, 3, 4, 5]);
    }

    #[test]
    fn two_slaves_of_one_kind_keep_their_own_bytes() {
        let mut held = HeldOutputs::default();
        let two = [slave(10, 0, 1), slave(10, 1, 1)];
        held.keep(&two, &[7, 9]);
        assert_eq!(held.image_for(&two, 2), [7, 9]);
    }

    #[test]
    fn new_or_resized_slaves_start_at_zero_and_clear_forgets() {
        let mut held = HeldOutputs::default();
        held.keep(&[slave(10, 0, 2)], &[1, 2]);
        assert_eq!(held.image_for(&[slave(10, 0, 3)], 3), [0, 0, 0], "remapped: another size");
        assert_eq!(held.image_for(&[slave(11, 0, 2)], 2), [0, 0], "another device");
        held.clear();
        assert_eq!(held.image_for(&[slave(10, 0, 2)], 2), [0, 0]);
    }
}
