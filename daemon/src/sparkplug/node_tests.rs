//! The node's rules (Sparkplug 3.0 chapters 6 and 7), on views built by
//! hand: births, deaths when slaves are lost or the network leaves OP,
//! data on change past a deadband, seq and bdSeq counting, commands'
//! targets.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::master::EcatState;
use ecmxf_devices::od::DataType;
use ecmxf_proto::sparkplug::payload::metric::Value as MetricValue;

use super::*;
use crate::config::sparkplug::MetricNames;
use crate::master::SlaveSummary;
use crate::master::image::Entry;

/// A network of three slaves: 0 with an output u16 and an input i16, 1
/// without process data, 2 with an output and an input byte.
struct World {
    snapshot: Snapshot,
    layout: NetworkLayout,
    image: Arc<Image>,
    inputs: Vec<u8>,
    outputs: Vec<u8>,
    al: BTreeMap<u8, (EcatState, u16)>,
}

fn entry(name: &str, slave: u8, output: bool, bit_offset: u32, data_type: DataType) -> Entry {
    Entry {
        name: name.into(),
        slave,
        index: if output { 0x7000 } else { 0x6000 },
        subindex: 1,
        output,
        bit_offset,
        bit_length: data_type.bits(),
        data_type,
        label: String::new(),
        variable: String::new(),
    }
}

impl World {
    fn new() -> Self {
        let slave =
            |name: &str| SlaveSummary { name: name.into(), vendor_id: 2, product_code: 7, ..SlaveSummary::default() };
        let mut image = Image::default();
        image.output_bytes = 3;
        image.input_bytes = 3;
        image.entries = vec![
            entry("0.setpoint", 0, true, 0, DataType::UInt16),
            entry("2.0x7000:01", 2, true, 16, DataType::UInt8),
            entry("0.actual", 0, false, 0, DataType::Int16),
            entry("2.0x6000:01", 2, false, 16, DataType::UInt8),
        ];
        Self {
            snapshot: Snapshot { phase: Phase::Running, ecat_state: EcatState::Op, slaves: 3, ..Snapshot::default() },
            layout: NetworkLayout {
                slaves: vec![slave("drive"), slave("coupler"), slave("io")],
                ..NetworkLayout::default()
            },
            image: Arc::new(image),
            inputs: vec![0; 3],
            outputs: vec![0; 3],
            al: BTreeMap::new(),
        }
    }

    fn view(&self, now_ms: u64) -> View<'_> {
        View {
            now_ms,
            snapshot: &self.snapshot,
            flowing: self.snapshot.phase == Phase::Running,
            health: "healthy",
            layout: &self.layout,
            image: Some(&self.image),
            inputs: &self.inputs,
            inputs_ms: now_ms.saturating_sub(3),
            outputs: &self.outputs,
            al: &self.al,
            cycle_us: 1000,
            exchange_rate: 0.0,
            counts: Counts::default(),
        }
    }
}

fn kinds(out: &[Outgoing]) -> Vec<(Kind, Option<u8>)> {
    out.iter().map(|o| (o.kind, o.device)).collect()
}

fn names(o: &Outgoing) -> Vec<&str> {
    o.payload.metrics.iter().filter_map(|m| m.name.as_deref()).collect()
}

#[test]
fn births_start_at_seq_zero_with_bdseq_and_every_device_alive() {
    let w = World::new();
    let mut node = Node::new(Settings::default());
    assert_eq!(node.next_connection(), 0);
    let out = node.birth(&w.view(10));
    use Kind::*;
    assert_eq!(kinds(&out), [(NBirth, None), (DBirth, Some(0)), (DBirth, Some(1)), (DBirth, Some(2))]);
    let seqs: Vec<u64> = out.iter().map(|o| o.payload.seq.unwrap()).collect();
    assert_eq!(seqs, [0, 1, 2, 3]);
    let nbirth = &out[0].payload;
    assert_eq!(nbirth.metrics[0].name.as_deref(), Some("bdSeq"));
    assert_eq!(nbirth.metrics[0].value, Some(MetricValue::LongValue(0)));
    assert!(names(&out[0]).contains(&REBIRTH));
    assert_eq!(names(&out[1])[7..], ["Outputs/setpoint", "Inputs/actual"]);
    assert_eq!(names(&out[2]).len(), 7, "slave 1 has no process data");
    assert_eq!(names(&out[3])[7..], ["Outputs/0x7000:01", "Inputs/0x6000:01"]);
    // Aliases are unique across the node and its devices.
    let mut aliases: Vec<u64> = out.iter().flat_map(|o| o.payload.metrics.iter().map(|m| m.alias.unwrap())).collect();
    let n = aliases.len();
    aliases.sort_unstable();
    aliases.dedup();
    assert_eq!(aliases.len(), n);
    // The will of this connection carries the same bdSeq, and no seq.
    let death = node.death(11);
    assert_eq!(death.seq, None);
    assert_eq!(death.metrics[0].value, Some(MetricValue::LongValue(0)));
}

#[test]
fn data_goes_out_by_alias_only_when_it_moved_past_the_deadband() {
    let mut w = World::new();
    let mut node = Node::new(Settings { data_deadband: 5.0, ..Settings::default() });
    node.next_connection();
    let births = node.birth(&w.view(10));
    assert!(node.update(&w.view(20), true).is_empty(), "nothing moved");
    w.inputs[0..2].copy_from_slice(&(-3i16).to_le_bytes());
    assert!(node.update(&w.view(30), true).is_empty(), "3 is within the deadband of 5");
    w.inputs[0..2].copy_from_slice(&(-9i16).to_le_bytes());
    w.inputs[2] = 200;
    let out = node.update(&w.view(40), true);
    assert_eq!(kinds(&out), [(Kind::DData, Some(0)), (Kind::DData, Some(2))]);
    let m = &out[0].payload.metrics[0];
    assert_eq!((m.name.as_deref(), m.datatype), (None, Some(SpType::Int16 as u32)));
    assert_eq!(m.value, Some(MetricValue::IntValue(u32::from((-9i16) as u16))));
    let born_alias =
        births[1].payload.metrics.iter().find(|b| b.name.as_deref() == Some("Inputs/actual")).unwrap().alias;
    assert_eq!(m.alias, born_alias);
    assert_eq!(out[1].payload.metrics[0].value, Some(MetricValue::IntValue(200)));
    assert_eq!(out.last().unwrap().payload.seq, Some(5));
}

#[test]
fn a_lost_slave_dies_alone_and_is_born_again_when_back() {
    let mut w = World::new();
    let mut node = Node::new(Settings::default());
    node.next_connection();
    node.birth(&w.view(0));
    // The ring ends before slave 2.
    w.snapshot.slaves = 2;
    let out = node.update(&w.view(1), false);
    assert_eq!(kinds(&out), [(Kind::DDeath, Some(2))]);
    assert_eq!(out[0].why, "the slave is gone from the ring", "the log says why");
    assert!(node.update(&w.view(2), true).is_empty());
    w.snapshot.slaves = 3;
    assert_eq!(kinds(&node.update(&w.view(3), false)), [(Kind::DBirth, Some(2))]);
    // An AL error of slave 1 kills slave 1 only.
    w.al.insert(1, (EcatState::SafeOp, 0x001A));
    let out = node.update(&w.view(4), false);
    assert_eq!(kinds(&out), [(Kind::DDeath, Some(1))]);
    assert_eq!(out[0].why, "the slave left OP (AL status)");
    w.al.clear();
    assert_eq!(kinds(&node.update(&w.view(5), false)), [(Kind::DBirth, Some(1))]);
    assert_eq!(node.born().collect::<Vec<_>>(), [0, 1, 2]);
}

#[test]
fn every_device_dies_when_the_network_leaves_op_and_a_new_image_means_new_births() {
    let mut w = World::new();
    let mut node = Node::new(Settings::default());
    node.next_connection();
    node.birth(&w.view(0));
    w.snapshot.phase = Phase::Recovering;
    let out = node.update(&w.view(1), true);
    assert_eq!(kinds(&out), [(Kind::DDeath, Some(0)), (Kind::DDeath, Some(1)), (Kind::DDeath, Some(2))]);
    assert!(out.iter().all(|o| o.payload.metrics.is_empty()));
    w.snapshot.phase = Phase::Running;
    assert_eq!(node.update(&w.view(2), false).len(), 3);
    // A new image with the same metrics (its devices named its entries):
    // nobody dies.
    let before = node.birth(&w.view(3));
    w.image = Arc::new((*w.image).clone());
    assert!(node.update(&w.view(4), false).is_empty(), "the same metrics are not a new birth");
    // Laid out again with other types (a new configuration): the devices
    // are born again with the new metrics, the aliases of names they had
    // kept.
    let mut retyped = (*w.image).clone();
    for e in &mut retyped.entries {
        e.data_type = DataType::Int64;
    }
    w.image = Arc::new(retyped);
    let out = node.update(&w.view(4), false);
    // Slave 1 has no process data: its metrics did not change.
    assert_eq!(
        kinds(&out),
        [(Kind::DDeath, Some(0)), (Kind::DDeath, Some(2)), (Kind::DBirth, Some(0)), (Kind::DBirth, Some(2))]
    );
    assert!(out.iter().filter(|o| o.kind == Kind::DDeath).all(|o| o.why.contains("laid out again")));
    assert!(out.iter().filter(|o| o.kind == Kind::DBirth).all(|o| !o.why.is_empty()));
    let alias_of =
        |o: &Outgoing, n: &str| o.payload.metrics.iter().find(|m| m.name.as_deref() == Some(n)).unwrap().alias;
    assert_eq!(alias_of(&before[1], "Outputs/setpoint"), alias_of(&out[2], "Outputs/setpoint"));
}

#[test]
fn seq_wraps_after_255_and_bdseq_after_255() {
    let mut w = World::new();
    let mut node = Node::new(Settings::default());
    for want in 0..=255 {
        assert_eq!(node.next_connection(), want);
    }
    assert_eq!(node.next_connection(), 0);
    node.birth(&w.view(0));
    let mut last = 3;
    for i in 0..300u32 {
        w.inputs[2] = (i % 2) as u8 + 1;
        for o in node.update(&w.view(u64::from(i)), true) {
            let seq = o.payload.seq.unwrap();
            assert_eq!(seq, (last + 1) % 256);
            last = seq;
        }
    }
}

#[test]
fn only_chosen_slaves_and_variables_are_published() {
    let w = World::new();
    let settings = Settings { slaves: vec![2], variables: vec!["2.0x6000:01".into()], ..Settings::default() };
    let mut node = Node::new(settings);
    node.next_connection();
    let out = node.birth(&w.view(0));
    assert_eq!(kinds(&out), [(Kind::NBirth, None), (Kind::DBirth, Some(2))]);
    assert_eq!(names(&out[1])[7..], ["Inputs/0x6000:01"]);
}

#[test]
fn commands_name_outputs_of_born_devices() {
    let w = World::new();
    let mut node = Node::new(Settings::default());
    node.next_connection();
    let out = node.birth(&w.view(0));
    let by_name = |n: &str| Metric { name: Some(n.into()), ..Metric::default() };
    let (i, image) = node.output_target(2, &by_name("Outputs/0x7000:01")).unwrap();
    assert_eq!(image.entries[i].name, "2.0x7000:01");
    let alias = out[3].payload.metrics.iter().find(|m| m.name.as_deref() == Some("Outputs/0x7000:01")).unwrap().alias;
    assert_eq!(node.output_target(2, &Metric { alias, ..Metric::default() }).unwrap().0, i);
    assert!(node.output_target(2, &by_name("Inputs/0x6000:01")).unwrap_err().contains("not an output variable"));
    assert!(node.output_target(2, &by_name("State")).unwrap_err().contains("not an output variable"));
    assert!(node.output_target(2, &by_name("nope")).unwrap_err().contains("no metric \"nope\""));
    assert!(node.output_target(9, &by_name("Outputs/0x7000:01")).unwrap_err().contains("not born"));
}

#[test]
fn node_data_carries_only_diagnostics_that_changed() {
    let mut w = World::new();
    let mut node = Node::new(Settings::default());
    node.next_connection();
    node.birth(&w.view(0));
    assert!(node.node_data(&w.view(1)).is_none());
    w.snapshot.exchanges = 1000;
    w.snapshot.crc_errors = 1;
    let out = node.node_data(&w.view(2)).unwrap();
    assert_eq!(out.kind, Kind::NData);
    assert_eq!(out.payload.metrics.len(), 2);
    assert!(out.payload.metrics.iter().all(|m| m.name.is_none() && m.alias.is_some()));
}

#[test]
fn label_names_where_unique_and_entry_names_elsewhere() {
    let mut w = World::new();
    let mut image = (*w.image).clone();
    image.entries[2].label = "Acceleration X".into();
    image.entries[0].label = "Setpoint".into();
    image.entries[1].label = "Same".into();
    image.entries[3].label = "Same".into(); // an input: unique among slave 2's inputs
    w.image = Arc::new(image);
    let mut node = Node::new(Settings { names: MetricNames::Label, ..Settings::default() });
    node.next_connection();
    let out = node.birth(&w.view(100));
    assert_eq!(names(&out[1])[7..], ["Outputs/Setpoint", "Inputs/Acceleration X"]);
    assert_eq!(names(&out[3])[7..], ["Outputs/Same", "Inputs/Same"]);
    // Input values carry their frame's time, the rest the publish time.
    let at = |o: &Outgoing, n: &str| o.payload.metrics.iter().find(|m| m.name.as_deref() == Some(n)).unwrap().timestamp;
    assert_eq!(at(&out[1], "Inputs/Acceleration X"), Some(97));
    assert_eq!(at(&out[1], "Outputs/Setpoint"), Some(100));
}

#[test]
fn a_label_two_entries_share_falls_back_to_entry_names() {
    let mut w = World::new();
    let mut image = (*w.image).clone();
    image.entries.push(entry("0.other", 0, false, 16, DataType::UInt8));
    image.entries[2].label = "Twice".into();
    image.entries[4].label = "Twice".into();
    w.image = Arc::new(image);
    let mut node = Node::new(Settings { names: MetricNames::Label, ..Settings::default() });
    node.next_connection();
    let out = node.birth(&w.view(0));
    assert_eq!(names(&out[1])[8..], ["Inputs/actual", "Inputs/other"]);
}

#[test]
fn a_node_started_again_goes_on_counting_bdseq() {
    let mut node = Node::new(Settings::default());
    node.resume(0);
    assert_eq!(node.next_connection(), 0, "first node of the process");
    let mut again = Node::new(Settings::default());
    again.resume(4);
    assert_eq!(again.next_connection(), 4);
    let mut wrap = Node::new(Settings::default());
    wrap.resume(256);
    assert_eq!(wrap.next_connection(), 0);
}
