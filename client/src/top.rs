//! `top`: a live terminal view (ratatui) of the master, the slaves, the
//! FIFO and counters, and plots of chosen input entries — what an engineer
//! leaves running in an SSH session while commissioning. `--once` renders
//! one frame as text (for scripts and tests); `--json` prints one snapshot
//! object per refresh instead of drawing.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use ratatui::Frame;
use ratatui::crossterm::event::{self, Event, KeyCode, KeyModifiers};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::Line;
use ratatui::widgets::{Axis, Block, Chart, Dataset, Gauge, GraphType, Paragraph, Row, Table};
use schemars::JsonSchema;
use serde::Serialize;
use tokio_stream::StreamExt;

use crate::cli::Top;
use crate::commands::master::CountersReport;
use crate::commands::pdo::layout;
use crate::commands::slaves::al_status;
use crate::connect::Api;
use crate::error::CliError;
use crate::output::Out;
use crate::values::{phase_name, state_name, value_json};

/// Seconds of history a plot shows.
const PLOT_SECONDS: f64 = 10.0;
/// Plot samples per second asked from the daemon.
const PLOT_RATE_HZ: u32 = 50;

/// One refresh of `ecmxfctl top --json` (NDJSON: one object per line).
#[derive(Debug, Serialize, JsonSchema, Default)]
pub struct TopSnapshot {
    pub phase: String,
    pub state: String,
    pub target_state: String,
    pub cycle_us: u32,
    pub rx_fifo_level: u32,
    pub fifo_rx_depth: u32,
    pub tx_fifo_level: u32,
    pub dc_stable: bool,
    pub output_writers: u32,
    pub counters: CountersReport,
    pub slaves: Vec<TopSlave>,
    /// Plotted entry -> newest value.
    pub plot: BTreeMap<String, serde_json::Value>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct TopSlave {
    pub position: u32,
    pub name: String,
    pub state: String,
    pub al_status_code: u32,
    pub al_status_text: String,
}

/// What the view shows: the newest snapshot and the plot history.
#[derive(Debug, Default)]
struct View {
    daemon: String,
    snap: TopSnapshot,
    history: Vec<(String, VecDeque<(f64, f64)>)>,
    now_s: f64,
    error: Option<String>,
}

async fn snapshot(api: &Api, cycle_us: u32) -> Result<TopSnapshot, CliError> {
    let info = api.master().get_info(api.req(pb::GetInfoRequest {})).await.map_err(CliError::rpc("master info"))?;
    let info = info.into_inner();
    let st = api.master().get_status(api.req(pb::GetStatusRequest {})).await.map_err(CliError::rpc("status"))?;
    let st = st.into_inner();
    let c = api.diagnostics().get_counters(api.req(pb::GetCountersRequest {})).await;
    let c = c.map_err(CliError::rpc("counters"))?.into_inner();
    Ok(TopSnapshot {
        phase: phase_name(st.phase).into(),
        state: state_name(st.ecat_state).into(),
        target_state: state_name(info.target_state).into(),
        cycle_us,
        rx_fifo_level: st.rx_fifo_level,
        fifo_rx_depth: info.fifo_rx_depth,
        tx_fifo_level: st.tx_fifo_level,
        dc_stable: st.dc_stable,
        output_writers: st.output_writers,
        counters: st.counters.into(),
        slaves: c
            .slaves
            .into_iter()
            .map(|s| TopSlave {
                position: s.position,
                name: s.name,
                state: state_name(s.state).into(),
                al_status_code: s.al_status_code,
                al_status_text: s.al_status_text,
            })
            .collect(),
        plot: BTreeMap::new(),
    })
}

fn as_f64(v: Option<&pb::Value>) -> Option<f64> {
    use pb::value::Kind;
    match v?.kind.as_ref()? {
        Kind::Integer(i) => Some(*i as f64),
        Kind::Unsigned(u) => Some(*u as f64),
        Kind::Real(f) => Some(*f),
        Kind::Boolean(b) => Some(f64::from(u8::from(*b))),
        _ => None,
    }
}

/// Runs the view until `q`, Esc or Ctrl-C (or one frame with --once).
pub async fn run(api: &Api, out: Out, t: &Top) -> Result<(), CliError> {
    let image = layout(api).await?;
    let plot: Vec<String> = if t.plot.is_empty() {
        // The first configured axis' actual position and velocity, named as
        // the layout names them ("1.position_actual", "1.axis2.velocity_actual").
        let axes = api.cia402().list_axes(api.req(pb::ListAxesRequest {})).await;
        let axes = axes.map_err(CliError::rpc("list axes"))?.into_inner().axes;
        // Without [[axis]]: the first drive-like slave in the image.
        let prefix = match axes.first() {
            Some(a) if a.slave_axis == 0 => Some(format!("{}.", a.slave)),
            Some(a) => Some(format!("{}.axis{}.", a.slave, a.slave_axis)),
            None => image
                .entries
                .iter()
                .find_map(|e| e.name.strip_suffix("position_actual").filter(|_| !e.is_output()).map(str::to_owned)),
        };
        prefix
            .map(|prefix| {
                ["position_actual", "velocity_actual"]
                    .iter()
                    .map(|n| format!("{prefix}{n}"))
                    .filter(|n| image.entries.iter().any(|e| &e.name == n))
                    .collect()
            })
            .unwrap_or_default()
    } else {
        for n in &t.plot {
            match image.entries.iter().find(|e| e.is_named(n)) {
                Some(e) if !e.is_output() => {}
                Some(_) => return Err(CliError::Usage(format!("--plot {n}: only inputs can be plotted"))),
                None => return Err(CliError::Usage(format!("--plot {n}: no such entry; `ecmxfctl pdos` lists them"))),
            }
        }
        t.plot.clone()
    };
    let mut view = View {
        daemon: api.target.clone(),
        history: plot.iter().map(|n| (n.clone(), VecDeque::new())).collect(),
        ..View::default()
    };
    let mut samples = if plot.is_empty() {
        None
    } else {
        let decimation = (1_000_000 / image.cycle_us.max(1) / PLOT_RATE_HZ).max(1);
        let req = pb::StreamInputsRequest { entries: plot.clone(), decimation, on_change: false };
        Some(api.pdo().stream_inputs(api.stream(req)).await.map_err(CliError::rpc("plot inputs"))?.into_inner())
    };
    view.snap = snapshot(api, image.cycle_us).await?;

    if t.once {
        // Collect a second of plot data, then draw one frame.
        let until = tokio::time::Instant::now() + Duration::from_secs(1);
        while let Some(s) = samples.as_mut() {
            tokio::select! {
                m = s.next() => match m { Some(Ok(m)) => absorb(&mut view, &m), _ => break },
                _ = tokio::time::sleep_until(until) => break,
            }
        }
        view.snap = snapshot(api, image.cycle_us).await?;
        fill_plot_values(&mut view);
        if out.json {
            out.line(&view.snap, String::new)?;
            return Ok(());
        }
        let backend = ratatui::backend::TestBackend::new(t.size.0, t.size.1);
        let mut term = ratatui::Terminal::new(backend)?;
        term.draw(|f| draw(f, &view))?;
        let buf = term.backend().buffer();
        let mut text = String::new();
        for y in 0..buf.area.height {
            let line: String = (0..buf.area.width).map(|x| buf[(x, y)].symbol().to_owned()).collect();
            text.push_str(line.trim_end());
            text.push('\n');
        }
        print!("{text}");
        return Ok(());
    }

    let mut term = if out.json { None } else { Some(ratatui::try_init()?) };
    let result = live(api, out, t, &image, &mut view, samples.as_mut(), term.as_mut()).await;
    if term.is_some() {
        ratatui::restore();
    }
    result
}

fn absorb(view: &mut View, m: &pb::InputSample) {
    let t = m.time_ns as f64 / 1e9;
    view.now_s = view.now_s.max(t);
    for (name, h) in &mut view.history {
        if let Some(v) = as_f64(m.values.iter().find(|v| &v.name == name).and_then(|v| v.value.as_ref())) {
            h.push_back((t, v));
            while h.front().is_some_and(|(t0, _)| *t0 < t - PLOT_SECONDS) {
                h.pop_front();
            }
        }
    }
}

fn fill_plot_values(view: &mut View) {
    view.snap.plot = view
        .history
        .iter()
        .map(|(n, h)| (n.clone(), h.back().map_or(serde_json::Value::Null, |(_, v)| value_json(Some(&real(*v))))))
        .collect();
}

fn real(v: f64) -> pb::Value {
    if v.fract() == 0.0 && v.abs() < 9e15 {
        pb::Value { kind: Some(pb::value::Kind::Integer(v as i64)) }
    } else {
        pb::Value { kind: Some(pb::value::Kind::Real(v)) }
    }
}

async fn live(
    api: &Api,
    out: Out,
    t: &Top,
    image: &crate::commands::pdo::LayoutReport,
    view: &mut View,
    mut samples: Option<&mut tonic::Streaming<pb::InputSample>>,
    mut term: Option<&mut ratatui::DefaultTerminal>,
) -> Result<(), CliError> {
    let mut refresh = tokio::time::interval(t.interval);
    let mut keys = tokio::time::interval(Duration::from_millis(50));
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    loop {
        tokio::select! {
            _ = refresh.tick() => {
                match snapshot(api, image.cycle_us).await {
                    Ok(s) => { view.snap = s; view.error = None; }
                    // Keep showing the last picture and say why it is old.
                    Err(e) if term.is_some() => view.error = Some(e.to_string()),
                    Err(e) => return Err(e),
                }
                fill_plot_values(view);
                match term.as_mut() {
                    Some(term) => { term.draw(|f| draw(f, view))?; }
                    None => out.line(&view.snap, String::new)?,
                }
            }
            m = async { match samples.as_mut() { Some(s) => s.next().await, None => std::future::pending().await } } => {
                match m {
                    Some(Ok(m)) => absorb(view, &m),
                    Some(Err(st)) => view.error = Some(format!("plot stream: {}", st.message())),
                    None => samples = None,
                }
            }
            _ = keys.tick(), if term.is_some() => {
                while event::poll(Duration::ZERO)? {
                    if let Event::Key(k) = event::read()? {
                        let ctrl_c = k.code == KeyCode::Char('c') && k.modifiers.contains(KeyModifiers::CONTROL);
                        if matches!(k.code, KeyCode::Char('q') | KeyCode::Esc) || ctrl_c {
                            return Ok(());
                        }
                    }
                }
            }
            _ = &mut ctrl_c => return Ok(()),
        }
    }
}

fn draw(f: &mut Frame, v: &View) {
    let s = &v.snap;
    let plots = v.history.len() as u16;
    let rows = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(1),
        Constraint::Length((s.slaves.len() as u16 + 3).min(12)),
        Constraint::Length(4),
        Constraint::Min(if plots > 0 { 6 } else { 0 }),
        Constraint::Length(1),
    ])
    .split(f.area());
    let bad = s.state != s.target_state || s.phase != "RUNNING";
    let title = format!(
        " ecmxf top  {}  phase {}  state {} (target {})  cycle {} us  DC {}  writers {}",
        v.daemon,
        s.phase,
        s.state,
        s.target_state,
        s.cycle_us,
        if s.dc_stable { "stable" } else { "NOT stable" },
        s.output_writers
    );
    let style = if bad { Style::default().fg(Color::Red) } else { Style::default().fg(Color::Green) };
    f.render_widget(Paragraph::new(title).style(style.add_modifier(Modifier::BOLD)), rows[0]);

    let ratio = f64::from(s.rx_fifo_level) / f64::from(s.fifo_rx_depth.max(1));
    let gauge = Gauge::default()
        .ratio(ratio.clamp(0.0, 1.0))
        .gauge_style(Style::default().fg(Color::Cyan))
        .label(format!("RxFIFO {}/{}  TxFIFO {}", s.rx_fifo_level, s.fifo_rx_depth, s.tx_fifo_level));
    f.render_widget(gauge, rows[1]);

    let slave_rows = s.slaves.iter().map(|x| {
        let row = Row::new(vec![
            x.position.to_string(),
            x.state.clone(),
            al_status(x.al_status_code, &x.al_status_text),
            x.name.clone(),
        ]);
        if x.state != s.target_state || x.al_status_code != 0 {
            row.style(Style::default().fg(Color::Red))
        } else {
            row
        }
    });
    let table = Table::new(
        slave_rows,
        [Constraint::Length(4), Constraint::Length(7), Constraint::Length(36), Constraint::Min(10)],
    )
    .header(Row::new(vec!["POS", "STATE", "AL STATUS", "NAME"]).style(Style::default().add_modifier(Modifier::BOLD)))
    .block(Block::bordered().title(" Slaves "));
    f.render_widget(table, rows[2]);

    let c = &s.counters;
    let counters = vec![
        Line::from(format!(
            "exchanges {}  frames in {} out {}  transactions {}  recoveries {}",
            c.exchanges, c.input_frames, c.output_frames, c.transactions, c.recoveries
        )),
        Line::from(format!(
            "CRC {}  WKC {}  corrupt {}  not-ready {}  FIFO alarms {}  max gap {} us  ring overflows {}",
            c.crc_errors,
            c.wkc_errors,
            c.corrupt_answers,
            c.not_ready_answers,
            c.fifo_alarms,
            c.max_fifo_gap_us,
            c.ring_overflows
        )),
    ];
    f.render_widget(Paragraph::new(counters).block(Block::bordered().title(" Counters ")), rows[3]);

    if plots > 0 {
        let areas = Layout::vertical(vec![Constraint::Ratio(1, u32::from(plots)); plots as usize]).split(rows[4]);
        for ((name, h), area) in v.history.iter().zip(areas.iter()) {
            plot(f, *area, name, h, v.now_s);
        }
    }
    let foot = match &v.error {
        Some(e) => Line::styled(format!(" {e}"), Style::default().fg(Color::Red)),
        None => Line::from(" q: quit"),
    };
    f.render_widget(Paragraph::new(foot), rows[5]);
}

fn plot(f: &mut Frame, area: Rect, name: &str, h: &VecDeque<(f64, f64)>, now: f64) {
    let points: Vec<(f64, f64)> = h.iter().copied().collect();
    let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(a, b), (_, y)| (a.min(*y), b.max(*y)));
    let (lo, hi) = if points.is_empty() {
        (0.0, 1.0)
    } else if lo == hi {
        (lo - 1.0, hi + 1.0)
    } else {
        (lo, hi)
    };
    let last = points.last().map_or("-".to_owned(), |(_, y)| y.to_string());
    let data = [Dataset::default().marker(Marker::Braille).graph_type(GraphType::Line).data(&points)];
    let chart = Chart::new(data.to_vec())
        .block(Block::bordered().title(format!(" {name} = {last} ")))
        .x_axis(Axis::default().bounds([now - PLOT_SECONDS, now]))
        .y_axis(Axis::default().bounds([lo, hi]).labels([format!("{lo:.0}"), format!("{hi:.0}")]));
    f.render_widget(chart, area);
}
