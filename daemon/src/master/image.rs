//! The process image, the master's (every front end, gRPC or any other,
//! reads the same one): every mapped PDO entry with a name, its variable name, its place in
//! the output or input image in bits, and its CoE type. Built
//! from each slave's assigned PDOs from the best source it has
//! ([`crate::master::pdos`]: CoE, else SII, else ESI) and the offsets
//! bring-up found. Also the bit-level get/put of entry values.
//!
//! The daemon builds it, not a caller ([`ImageCache::keep_built`]): once
//! the network runs after each bring-up, as its own client on the blocking
//! slot (every other turn, see [`Call::daemon`]), several
//! slaves at a time, and keeps it across recoveries that find the same
//! network. A call that needs it before it is ready waits for that one
//! build; its deadline can end the wait, never the work (when the build
//! ran inside the first caller's deadline, a busy daemon threw it away
//! call after call).

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use ecmxf_devices::od::DataType;
use tokio::sync::{Notify, watch};

use super::objects::{entry_name, lookup};
use super::pdos::{PdoDescription, PdoSource, SlavePdos};
use super::{Call, EngineError, Master, NotRunning, Phase, SlaveSummary};

/// Slaves whose PDOs are read at once: each read waits for the chip, so
/// with a few in flight the next request is always queued when the slot
/// frees.
const BUILDERS: usize = 4;

/// One entry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Entry {
    /// Unique name.
    pub name: String,
    /// Slave position.
    pub slave: u8,
    /// Object index (0: a gap in the mapping).
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Output (true) or input.
    pub output: bool,
    /// From the start of its image, bits.
    pub bit_offset: u32,
    /// Size, bits.
    pub bit_length: u32,
    /// Type: the device's, else the standard object's, else one of the
    /// bit length ([`type_for_bits`]).
    pub data_type: DataType,
    /// The device's name for it ("" when none).
    pub label: String,
    /// Its variable name as configuration tools write it ("" when none):
    /// the ENI's (`WheelRearLeft.Inputs.Status word`), else
    /// `<slave>.<PDO name>.<entry name>` from the device's description.
    pub variable: String,
}

/// The whole image.
#[derive(Clone, Debug, Default)]
pub struct Image {
    /// Output image bytes.
    pub output_bytes: u32,
    /// Input image bytes.
    pub input_bytes: u32,
    /// Entries, outputs then inputs, slave order.
    pub entries: Vec<Entry>,
    by_name: HashMap<String, usize>,
    by_variable: HashMap<String, usize>,
    /// What the layout disagrees with: an ENI variable no entry matches.
    pub notes: Vec<String>,
    /// The configuration generation it was built for.
    pub generation: u64,
    /// Cycle, us.
    pub cycle_us: u32,
    /// Each slave's PDOs as the image was built from them, by position.
    pub mappings: Vec<Arc<SlavePdos>>,
}

impl Image {
    /// Reads the PDOs of every slave with process data, `BUILDERS` slaves
    /// at a time, and lays them out as bring-up placed them (`key`).
    pub(crate) async fn build(master: &Arc<Master>, key: &LayoutKey) -> Result<Self, EngineError> {
        let mappings = read_all_pdos(master, &key.slaves).await?;
        Ok(Self::lay_out(master, key, mappings))
    }

    /// This image again with the names its slaves' devices give the
    /// entries no other source named (SDO Information, see
    /// [`Master::name_from_device`]), or `None` when none does. Names only
    /// add: the entries, offsets and types are this image's.
    pub(crate) async fn named_by_devices(&self, master: &Arc<Master>, key: &LayoutKey) -> Option<Self> {
        let mut mappings = self.mappings.clone();
        let mut named = false;
        // Each identity's device is asked once; its twins take its names
        // (`SlavePdos::named_as`): a line of 100 identical IO slaves
        // costs one device's questions, not a hundred.
        let mut asked: Vec<((u32, u32, u32), SlavePdos)> = Vec::new();
        for (slave, m) in mappings.iter_mut().enumerate().filter(|(_, m)| m.device_can_name) {
            let mut pdos = SlavePdos::clone(m);
            pdos.device_can_name = false;
            let identity = key.slaves.get(slave).map(|s| (s.vendor_id, s.product_code, s.revision));
            let twin = asked.iter().find(|(id, _)| Some(*id) == identity).map(|(_, t)| t);
            if let Some(twin) = twin {
                pdos.named_as(twin);
            }
            // A twin mapping the same objects was asked already: what it
            // could not name, this device cannot either.
            if !pdos.all_named() && !twin.is_some_and(|t| same_objects(t, &pdos)) {
                master.name_from_device(slave as u8, &mut pdos, Call::daemon()).await;
                if let Some(id) = identity {
                    asked.retain(|(known, _)| *known != id);
                    asked.push((id, pdos.clone()));
                }
            }
            if pdos != **m {
                *m = Arc::new(pdos);
                named = true;
            }
        }
        if !named {
            return None;
        }
        let mut image = Self::lay_out(master, key, mappings);
        // The types stay the first image's (a value is never read or
        // written as two types in one layout).
        for (e, before) in image.entries.iter_mut().zip(&self.entries) {
            e.data_type = before.data_type;
        }
        Some(image)
    }

    /// The image of `mappings` as bring-up placed them (`key`).
    fn lay_out(master: &Master, key: &LayoutKey, mappings: Vec<Arc<SlavePdos>>) -> Self {
        // One copy of the configuration for the whole build.
        let config = master.config();
        let mut image = Image {
            output_bytes: key.rx_size as u32,
            input_bytes: key.tx_size as u32,
            generation: key.generation,
            cycle_us: config.cycle.sync0_us,
            mappings,
            ..Image::default()
        };
        for output in [true, false] {
            for (i, s) in key.slaves.iter().enumerate() {
                let (bytes, offset) = if output { (s.rx_bytes, s.rx_offset) } else { (s.tx_bytes, s.tx_offset) };
                let pdos = Arc::clone(&image.mappings[i]);
                let list = if output { &pdos.rx } else { &pdos.tx };
                if let Some(note) = described_differently(i, &s.name, output, bytes, &pdos) {
                    image.notes.push(note);
                }
                if bytes == 0 {
                    continue;
                }
                let first = image.entries.len();
                image.add_slave(i as u8, output, (offset * 8) as u32, (bytes * 8) as u32, list);
                let slave = config.slaves.get(i).cloned().unwrap_or_default();
                image.name_variables(first, &slave, output, (offset * 8) as u32);
            }
        }
        image
    }

    /// Names the entries of one slave's outputs or inputs (from `first`
    /// on, its data starting at bit `start`) with their variables: the
    /// ENI's, placed by offset and size from the slave's start, where the
    /// configuration came from one (an ENI variable no entry matches is a
    /// note: the network's mapping is not the file's); else each entry's
    /// `<slave>.<PDO>.<entry>` from the device's names.
    fn name_variables(&mut self, first: usize, config: &crate::config::SlaveConfig, output: bool, start: u32) {
        let dir = if output { "outputs" } else { "inputs" };
        let mine: Vec<_> = config.variables.iter().filter(|v| v.output == output).collect();
        let mut names: Vec<(usize, String)> = Vec::new();
        if !mine.is_empty() {
            // The ENI's type wins where it has one: the tool read it from
            // the device's description, the mapping read over CoE has none.
            for v in mine {
                let hit = (first..self.entries.len()).find(|&k| {
                    let e = &self.entries[k];
                    e.index != 0 && e.bit_offset - start == v.bit && e.bit_length == v.bits
                });
                match hit {
                    Some(k) => {
                        if let Some(t) = v.data_type {
                            self.entries[k].data_type = t;
                        }
                        names.push((k, v.name.clone()));
                    }
                    None => {
                        let slave = self.entries.get(first).map_or(0, |e| e.slave);
                        self.notes.push(format!(
                            "ENI variable {:?} ({}): slave {slave}'s {dir} have no {}-bit entry at bit {}: the \
                             network's mapping is not the file's",
                            v.name, v.at, v.bits, v.bit
                        ));
                    }
                }
            }
        } else {
            let prefix = match &config.name {
                Some(n) => n.clone(),
                None => self.entries.get(first).map_or_else(String::new, |e| e.slave.to_string()),
            };
            for (k, e) in self.entries.iter().enumerate().skip(first) {
                if let Some(rest) = e.variable.strip_prefix('.') {
                    names.push((k, format!("{prefix}.{rest}")));
                }
            }
        }
        for e in &mut self.entries[first..] {
            e.variable.clear();
        }
        for (k, name) in names {
            let mut unique = name.clone();
            let mut n = 2;
            while self.by_variable.contains_key(&unique) || self.by_name.contains_key(&unique) {
                unique = format!("{name}#{n}");
                n += 1;
            }
            self.by_variable.insert(unique.clone(), k);
            self.entries[k].variable = unique;
        }
    }

    fn add_slave(&mut self, slave: u8, output: bool, start: u32, bits: u32, pdos: &[PdoDescription]) {
        let mut at = start;
        for pdo in pdos {
            for e in &pdo.entries {
                let len = u32::from(e.bits);
                if e.index != 0 && at + len <= start + bits {
                    let data_type = e.data_type.unwrap_or_else(|| {
                        lookup(e.index, e.subindex)
                            .map(|(k, _)| k.data_type)
                            // A string mapped in part keeps its type, in
                            // whole bytes; a few bits of one are a number.
                            .filter(|t| {
                                matches!(t, DataType::VisibleString(_) | DataType::OctetString(_)) && len % 8 == 0
                                    || t.bits() == len
                            })
                            .unwrap_or_else(|| type_for_bits(len))
                    });
                    self.push(Entry {
                        name: entry_name(slave, e.index, e.subindex),
                        slave,
                        index: e.index,
                        subindex: e.subindex,
                        output,
                        bit_offset: at,
                        bit_length: len,
                        data_type,
                        label: e.name.clone(),
                        // ".<PDO>.<entry>": `name_variables` puts the
                        // slave in front, or the ENI's name instead.
                        variable: if pdo.name.is_empty() || e.name.is_empty() {
                            String::new()
                        } else {
                            format!(".{}.{}", pdo.name, e.name)
                        },
                    });
                }
                at += len;
            }
        }
        // A source that describes less than the slave's bytes (no source at
        // all, or one that disagrees with the slave): the rest stays
        // reachable by offset, as one entry.
        if at < start + bits {
            let dir = if output { "outputs" } else { "inputs" };
            self.push(Entry {
                name: format!("{slave}.more_{dir}"),
                slave,
                index: 0,
                subindex: 0,
                output,
                bit_offset: at,
                bit_length: start + bits - at,
                data_type: DataType::OctetString(((start + bits - at) / 8) as u16),
                label: String::new(),
                variable: String::new(),
            });
        }
    }

    fn push(&mut self, mut e: Entry) {
        let mut n = 2;
        let base = e.name.clone();
        while self.by_name.contains_key(&e.name) {
            e.name = format!("{base}#{n}");
            n += 1;
        }
        self.by_name.insert(e.name.clone(), self.entries.len());
        self.entries.push(e);
    }

    /// An entry by name, or by variable name.
    pub(crate) fn get(&self, name: &str) -> Option<&Entry> {
        self.by_name.get(name).or_else(|| self.by_variable.get(name)).map(|&i| &self.entries[i])
    }

    /// The input entry of `slave` for CiA 402 object `index`.
    pub(crate) fn find(&self, slave: u8, index: u16, output: bool) -> Option<&Entry> {
        self.entries.iter().find(|e| e.slave == slave && e.index == index && e.subindex == 0 && e.output == output)
    }
}

/// Reads `bits` bits at bit `offset` of `image` (little-endian, LSB first).
pub(crate) fn read_bits(image: &[u8], offset: u32, bits: u32) -> Vec<u8> {
    let mut out = vec![0u8; bits.div_ceil(8) as usize];
    for i in 0..bits {
        let src = offset + i;
        let Some(byte) = image.get((src / 8) as usize) else { break };
        if byte >> (src % 8) & 1 == 1 {
            out[(i / 8) as usize] |= 1 << (i % 8);
        }
    }
    out
}

/// Writes `bits` bits of `value` at bit `offset` of `image`.
pub(crate) fn write_bits(image: &mut [u8], offset: u32, bits: u32, value: &[u8]) {
    for i in 0..bits {
        let dst = offset + i;
        let bit = value.get((i / 8) as usize).is_some_and(|b| b >> (i % 8) & 1 == 1);
        if let Some(byte) = image.get_mut((dst / 8) as usize) {
            if bit {
                *byte |= 1 << (dst % 8);
            } else {
                *byte &= !(1 << (dst % 8));
            }
        }
    }
}

/// A type of `bits` bits when nothing better is known: unsigned, BOOL for
/// one bit, octets for odd sizes.
pub(crate) fn type_for_bits(bits: u32) -> DataType {
    match bits {
        1 => DataType::Bool,
        8 => DataType::UInt8,
        16 => DataType::UInt16,
        32 => DataType::UInt32,
        64 => DataType::UInt64,
        n => DataType::OctetString(n.div_ceil(8) as u16),
    }
}

/// Every slave's PDOs, in ring order: [`BUILDERS`] tasks take the next
/// slave until none is left; the first error ends the build (the tasks
/// still running are dropped with it).
async fn read_all_pdos(master: &Arc<Master>, slaves: &[SlaveSummary]) -> Result<Vec<Arc<SlavePdos>>, EngineError> {
    let next = Arc::new(AtomicUsize::new(0));
    let sizes: Arc<[(usize, usize)]> = slaves.iter().map(|s| (s.rx_bytes, s.tx_bytes)).collect();
    let mut tasks = tokio::task::JoinSet::new();
    for _ in 0..BUILDERS.min(slaves.len()) {
        let (master, next, sizes) = (Arc::clone(master), Arc::clone(&next), Arc::clone(&sizes));
        tasks.spawn(async move {
            let mut done = Vec::new();
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(rx, tx)) = sizes.get(i) else { return Ok(done) };
                done.push((i, master.slave_pdos(i as u8, rx, tx, Call::daemon()).await?));
            }
        });
    }
    let mut out: Vec<Option<Arc<SlavePdos>>> = vec![None; slaves.len()];
    while let Some(joined) = tasks.join_next().await {
        let done = joined.map_err(|e| EngineError::Failed(format!("reading the PDOs: {e}")))??;
        for (i, pdos) in done {
            out[i] = Some(Arc::new(pdos));
        }
    }
    Ok(out.into_iter().map(|p| p.unwrap_or_else(|| Arc::new(SlavePdos::none("not read")))).collect())
}

/// Whether two slaves map the same objects, PDO by PDO.
fn same_objects(a: &SlavePdos, b: &SlavePdos) -> bool {
    let objects = |l: &[PdoDescription]| -> Vec<(u16, Vec<(u16, u8)>)> {
        l.iter().map(|p| (p.index, p.entries.iter().map(|e| (e.index, e.subindex)).collect())).collect()
    };
    objects(&a.rx) == objects(&b.rx) && objects(&a.tx) == objects(&b.tx)
}

/// What an image is valid for: the configuration in force and the network
/// bring-up found (identities, process data sizes and offsets). A recovery
/// that finds the same keeps the image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct LayoutKey {
    generation: u64,
    slaves: Vec<SlaveSummary>,
    rx_size: usize,
    tx_size: usize,
}

impl LayoutKey {
    /// The master's now.
    pub(crate) fn of(master: &Master) -> Self {
        let generation = master.status().config_generation;
        let layout = master.layout();
        Self { generation, slaves: layout.slaves, rx_size: layout.rx_size, tx_size: layout.tx_size }
    }
}

/// One build's outcome.
#[derive(Clone, Debug)]
pub(crate) struct Built {
    key: LayoutKey,
    result: Result<Arc<Image>, EngineError>,
}

/// The image of the network in force, kept built by the daemon.
#[derive(Debug)]
pub(crate) struct ImageCache {
    built: watch::Sender<Option<Built>>,
    /// A caller found a failed build and wants another try.
    wanted: Notify,
}

impl Default for ImageCache {
    fn default() -> Self {
        Self { built: watch::Sender::new(None), wanted: Notify::new() }
    }
}

impl ImageCache {
    /// The image for the network in force: at once when built; otherwise
    /// after the build under way (or a new try, when the last one failed)
    /// ends. A network that does not run and has no image is an error at
    /// once: nothing would build one.
    pub(crate) async fn get(&self, master: &Master) -> Result<Arc<Image>, EngineError> {
        let mut built = self.built.subscribe();
        let mut asked = false;
        loop {
            let key = LayoutKey::of(master);
            match built.borrow_and_update().as_ref().filter(|b| b.key == key).map(|b| &b.result) {
                Some(Ok(image)) => return Ok(Arc::clone(image)),
                Some(Err(e)) if asked => return Err(e.clone()),
                _ => {}
            }
            let phase = master.status().phase;
            if phase != Phase::Running {
                return Err(EngineError::Unavailable(NotRunning::Phase { phase, last_error: master.last_error() }));
            }
            if !asked {
                self.wanted.notify_one();
                asked = true;
            }
            if built.changed().await.is_err() {
                return Err(EngineError::Unavailable(NotRunning::Stopped));
            }
        }
    }

    /// Changes with each build, naming or failure.
    pub(crate) fn changes(&self) -> watch::Receiver<Option<Built>> {
        self.built.subscribe()
    }

    /// The image for the network in force if one was built (or its build
    /// failed), without waiting or asking for one: for front ends that
    /// publish on their own clock (Sparkplug) and try again next time.
    pub(crate) fn current(&self, master: &Master) -> Option<Result<Arc<Image>, EngineError>> {
        let key = LayoutKey::of(master);
        self.built.borrow().as_ref().filter(|b| b.key == key).map(|b| b.result.clone())
    }

    /// The daemon's builder, for as long as it runs: builds the image each
    /// time the network runs with a layout it has none for, and again after
    /// a failed build once the engine's phase, state or configuration
    /// changes or a caller asks. Waits on the engine's status changes (not
    /// on its periodic snapshots) and on callers; idle otherwise.
    pub(crate) async fn keep_built(&self, master: Arc<Master>) {
        let mut status = master.watch_status();
        let mut just_failed = false;
        loop {
            let seen = status.borrow_and_update().key();
            if seen.0 == Phase::Running && !just_failed {
                let key = LayoutKey::of(&master);
                let have = self.built.borrow().as_ref().is_some_and(|b| b.key == key && b.result.is_ok());
                if !have {
                    let started = Instant::now();
                    let result = Image::build(&master, &key).await.map(Arc::new);
                    let took_ms = started.elapsed().as_millis() as u64;
                    match &result {
                        Ok(i) => {
                            tracing::info!(
                                slaves = key.slaves.len(),
                                entries = i.entries.len(),
                                took_ms,
                                "process image laid out"
                            );
                            for n in &i.notes {
                                tracing::warn!(target: "ecmxfd::api::image", "{n}");
                            }
                        }
                        Err(e) => tracing::warn!(took_ms, "process image not laid out: {e}"),
                    }
                    just_failed = result.is_err();
                    self.built.send_replace(Some(Built { key: key.clone(), result: result.clone() }));
                    // Then the devices' own names, in a second pass: the
                    // first image never waits for them.
                    if let Ok(first) = result {
                        self.name_by_devices(&master, &key, &first).await;
                    }
                    continue;
                }
            }
            tokio::select! {
                r = status.wait_for(|s| s.key() != seen) => if r.is_err() { return },
                () = self.wanted.notified() => {}
            }
            just_failed = false;
        }
    }
}

impl ImageCache {
    /// Replaces `first` with the image its devices name, if they do and
    /// the network is still the one it was built for.
    async fn name_by_devices(&self, master: &Arc<Master>, key: &LayoutKey, first: &Image) {
        let started = Instant::now();
        let Some(named) = first.named_by_devices(master, key).await else { return };
        let labels = |i: &Image| i.entries.iter().filter(|e| !e.label.is_empty()).count();
        let added = labels(&named).saturating_sub(labels(first));
        let mut named = Some(named);
        let still = self.built.send_if_modified(|b| match (b, named.take()) {
            (Some(b), Some(named)) if b.key == *key && b.result.as_ref().is_ok_and(|i| std::ptr::eq(&**i, first)) => {
                b.result = Ok(Arc::new(named));
                true
            }
            _ => false,
        });
        if still {
            tracing::info!(
                named = added,
                took_ms = started.elapsed().as_millis() as u64,
                "process image entries named by their devices"
            );
        }
    }
}

/// What the chip made of a slave's data in one direction, when it is not
/// what the slave's PDOs (from their best source) describe: PDOs listed but
/// no bytes placed (a PDO on a sync manager the device lacks, an assignment
/// the chip did not read), or bytes of another size. Each is a note of the
/// layout (`ecmxfctl pdos`, GetLayout, the log at start): the entries past
/// what the description covers stay reachable by offset as
/// `N.more_outputs`/`N.more_inputs`.
fn described_differently(slave: usize, name: &str, output: bool, bytes: usize, pdos: &SlavePdos) -> Option<String> {
    let list = if output { &pdos.rx } else { &pdos.tx };
    let bits: u32 = list.iter().flat_map(|p| &p.entries).map(|e| u32::from(e.bits)).sum();
    if list.is_empty() || bits.div_ceil(8) as usize == bytes {
        return None;
    }
    let (dir, kind) = if output { ("output", "RxPDOs") } else { ("input", "TxPDOs") };
    let from = match pdos.source {
        PdoSource::Coe => "read over CoE",
        PdoSource::Sii => "from its SII",
        PdoSource::Esi => "from its ESI",
        PdoSource::None => "from no source",
    };
    let indexes: Vec<String> = list.iter().map(|p| format!("{:#06x}", p.index)).collect();
    let why = if pdos.note.is_empty() { String::new() } else { format!(" ({})", pdos.note) };
    Some(if bytes == 0 {
        format!(
            "slave {slave} ({name}): its {kind} {} ({bits} bits, {from}{why}) have no {dir} bytes in the frames: the \
             chip placed none (a PDO on a sync manager the device lacks, or an assignment it did not read)",
            indexes.join(", ")
        )
    } else {
        format!(
            "slave {slave} ({name}): the chip placed {bytes} {dir} bytes; its {kind} {} ({from}{why}) describe {bits} \
             bits: what they do not cover is reachable by offset as {slave}.more_{dir}s",
            indexes.join(", ")
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::pdos::EntryDescription;

    #[test]
    fn pdos_the_chip_placed_otherwise_are_named_with_their_source() {
        let entry = |bits| EntryDescription { index: 0x6000, subindex: 1, bits, name: String::new(), data_type: None };
        let pdo = |entries| PdoDescription { index: 0x1A00, name: String::new(), sync_manager: Some(3), entries };
        let pdos = SlavePdos {
            source: PdoSource::Sii,
            note: "CoE: no mailbox".into(),
            names_from: crate::master::pdos::NameSource::None,
            device_can_name: false,
            rx: Vec::new(),
            tx: vec![pdo(vec![entry(8), entry(4)])],
        };
        assert_eq!(described_differently(2, "IO", false, 2, &pdos), None, "12 bits in 2 bytes");
        assert_eq!(described_differently(2, "IO", true, 0, &pdos), None, "nothing described, nothing placed");
        let none = described_differently(2, "IO", false, 0, &pdos).unwrap();
        assert!(
            none.starts_with(
                "slave 2 (IO): its TxPDOs 0x1a00 (12 bits, from its SII (CoE: no mailbox)) have no input bytes"
            ),
            "{none}"
        );
        let other = described_differently(2, "IO", false, 4, &pdos).unwrap();
        assert!(other.contains("the chip placed 4 input bytes") && other.contains("2.more_inputs"), "{other}");
    }

    #[test]
    fn bits_round_trip_at_any_offset() {
        for offset in 0..20 {
            for bits in [1, 3, 8, 13, 16, 32] {
                let mut image = vec![0xA5u8; 8];
                let before = image.clone();
                let value = 0x1234_5678u32.to_le_bytes();
                write_bits(&mut image, offset, bits, &value);
                let back = read_bits(&image, offset, bits);
                let mask = if bits == 32 { u32::MAX } else { (1 << bits) - 1 };
                let mut b = [0u8; 4];
                b[..back.len()].copy_from_slice(&back);
                assert_eq!(u32::from_le_bytes(b), 0x1234_5678 & mask, "offset {offset} bits {bits}");
                // Bits outside the entry are untouched.
                for i in 0..64 {
                    if i < offset || i >= offset + bits {
                        let bit = |img: &[u8]| img[(i / 8) as usize] >> (i % 8) & 1;
                        assert_eq!(bit(&image), bit(&before));
                    }
                }
            }
        }
    }
}
