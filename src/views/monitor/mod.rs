//! `vic monitor` on a terminal: a live view of one board (issue 15, item 4). The board's mode as a
//! banner, rolling plots of the joints, the stiffness and the torque over the last seconds, the
//! loop's wake-up jitter and late ticks, the command age, rejections by reason, the disturbances in
//! force; and keys that push the arm, so a person can see stiffness reject a push.
//!
//! Three parts, after the model/view split of ratatui's own examples: [`App`] is the pure state
//! (updated from the board's states and telemetry, a key turns into an [`Action`]), [`draw`] renders
//! an `App` into a frame (tested with ratatui's `TestBackend`), and [`run`] is the thin terminal
//! loop (raw mode, the transport, the keys, sending what an action asks through
//! [`crate::views::operator::inject`]).

mod draw;
mod run;

pub(crate) use draw::draw;
pub(crate) use run::run;

use crate::views::operator::{Ack, OperatorError, Request, Status};
use std::collections::VecDeque;
use vic_rt::transport::{CENTRAL_NODE, MAX_JOINTS, NodeInfo, NodeLiveness, StateMsg, Telemetry};

/// What the keys send and how much history the plots keep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Settings {
    /// Torque of a pulse [N m] (`p`: +, `P`: −).
    pub(crate) pulse_torque: f64,
    /// Pulse duration [s].
    pub(crate) pulse_duration: f64,
    /// β of the field `f` switches on [N/m].
    pub(crate) field_beta: f64,
    /// Seconds of history in the plots.
    pub(crate) window_s: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            pulse_torque: 2.0,
            pulse_duration: 0.1,
            field_beta: 50.0,
            window_s: 10.0,
        }
    }
}

/// A key as the monitor sees it (the terminal loop translates the terminal's events).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Key {
    Char(char),
    Esc,
    /// Ctrl-C (raw mode turns it into a key, not a signal).
    CtrlC,
}

/// What a key asks the terminal loop to do.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Action {
    /// Nothing (an unbound key, or one that only changed the view).
    None,
    /// Restore the terminal and exit 0.
    Quit,
    /// Send these disturbances to the board, in order; `label` names them in the event log.
    Send {
        label: String,
        requests: Vec<Request>,
    },
}

/// The states kept per plot: one sample every [`SAMPLE_S`] of board time.
const SAMPLE_S: f64 = 0.01;
/// Lines kept in the event log.
const LOG_LINES: usize = 6;

/// A rolling series of (time [s], value) points, oldest first.
#[derive(Debug, Clone, Default)]
pub(crate) struct Series {
    points: VecDeque<(f64, f64)>,
}

impl Series {
    fn push(&mut self, t: f64, v: f64, window_s: f64) {
        if v.is_finite() {
            self.points.push_back((t, v));
        }
        while self.points.front().is_some_and(|p| p.0 < t - window_s) {
            self.points.pop_front();
        }
    }
    /// The points, oldest first.
    pub(crate) fn points(&self) -> Vec<(f64, f64)> {
        self.points.iter().copied().collect()
    }
    /// Smallest and largest value, `None` when empty.
    pub(crate) fn range(&self) -> Option<(f64, f64)> {
        self.points.iter().fold(None, |r, &(_, v)| match r {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
    }
    /// The series less its mean (itself when empty).
    pub(crate) fn centred(&self) -> Series {
        let n = self.points.len().max(1) as f64;
        let mean = self.points.iter().map(|p| p.1).sum::<f64>() / n;
        Series {
            points: self.points.iter().map(|&(t, v)| (t, v - mean)).collect(),
        }
    }
    fn clear(&mut self) {
        self.points.clear();
    }
}

/// Per-joint series of one quantity.
pub(crate) type JointSeries = [Series; MAX_JOINTS];

/// The plot's y bounds for `series`: the data's range padded by 10 % of its span on each side,
/// at least `min_span` wide (a flat line sits in the middle), `[-1, 1]·min_span/2` with no data.
pub(crate) fn bounds(series: &[&Series], min_span: f64) -> [f64; 2] {
    let range = series
        .iter()
        .filter_map(|s| s.range())
        .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
    let (lo, hi) = range.unwrap_or((0.0, 0.0));
    let pad = 0.1 * (hi - lo);
    let (lo, hi) = (lo - pad, hi + pad);
    if hi - lo < min_span {
        let mid = 0.5 * (lo + hi);
        [mid - 0.5 * min_span, mid + 0.5 * min_span]
    } else {
        [lo, hi]
    }
}

/// The live view's state: the last telemetry, the plots' history, the operator's actions and
/// what the board made of them. No terminal, no transport: the tests drive it directly.
#[derive(Debug, Clone)]
pub(crate) struct App {
    pub(crate) namespace: String,
    pub(crate) settings: Settings,
    /// The last telemetry, `None` until a board answered.
    pub(crate) status: Option<Status>,
    /// Whether the board has gone quiet (no telemetry for a while) after answering.
    pub(crate) stale: bool,
    /// Joints of the board (from its states and telemetry).
    pub(crate) joints: usize,
    /// The joint `p` pushes (0-based).
    pub(crate) joint: usize,
    /// Board time of the newest sample [s] (monotonic, from the board's time stamps).
    pub(crate) now_s: f64,
    pub(crate) q: JointSeries,
    pub(crate) stiffness: JointSeries,
    pub(crate) tau: JointSeries,
    pub(crate) tau_ext: JointSeries,
    /// Distance to the commanded equilibrium [rad], from telemetry.
    pub(crate) tracking_error: Series,
    /// Wake-up jitter p99 per telemetry interval [µs], newest last.
    pub(crate) jitter_p99: VecDeque<u64>,
    /// Late ticks per telemetry interval, newest last.
    pub(crate) late_per_interval: VecDeque<u64>,
    last_late: Option<u64>,
    last_sample_s: f64,
    /// Whether a central process (`vic-planner`) is alive in the namespace, from the last look
    /// at its nodes (`None` before the first).
    pub(crate) central: Option<bool>,
    /// Pulses sent and acknowledged by the board.
    pub(crate) pulses_sent: u64,
    pub(crate) pulses_acked: u64,
    /// What happened, newest last.
    pub(crate) log: VecDeque<String>,
}

fn seconds(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

impl App {
    pub(crate) fn new(namespace: &str, settings: Settings) -> App {
        App {
            namespace: namespace.into(),
            settings,
            status: None,
            stale: false,
            joints: 1,
            joint: 0,
            now_s: 0.0,
            q: Default::default(),
            stiffness: Default::default(),
            tau: Default::default(),
            tau_ext: Default::default(),
            tracking_error: Series::default(),
            jitter_p99: VecDeque::new(),
            late_per_interval: VecDeque::new(),
            last_late: None,
            last_sample_s: f64::NEG_INFINITY,
            pulses_sent: 0,
            pulses_acked: 0,
            log: VecDeque::new(),
            central: None,
        }
    }

    /// Telemetry intervals kept in the jitter and late-tick sparklines (the plots' window at the
    /// board's 10 Hz telemetry).
    fn intervals(&self) -> usize {
        (self.settings.window_s * 10.0).ceil().max(1.0) as usize
    }

    /// A state from the board's 1 kHz stream: kept every [`SAMPLE_S`] of board time.
    pub(crate) fn on_state(&mut self, s: &StateMsg) {
        let t = seconds(s.header.time_ns);
        self.joints = (s.joints as usize).clamp(1, MAX_JOINTS);
        self.joint = self.joint.min(self.joints - 1);
        // 0.1 ms of slack: a board tick a little early still starts the next sample.
        if t < self.last_sample_s + SAMPLE_S - 1e-4 && t >= self.last_sample_s {
            return;
        }
        self.last_sample_s = t;
        self.now_s = self.now_s.max(t);
        let w = self.settings.window_s;
        for j in 0..self.joints {
            self.q[j].push(t, s.q[j], w);
            self.stiffness[j].push(t, s.stiffness[j], w);
            self.tau[j].push(t, s.tau[j], w);
            self.tau_ext[j].push(t, s.tau_ext[j], w);
        }
    }

    /// A telemetry message (every 100 ticks).
    pub(crate) fn on_telemetry(&mut self, t: &Telemetry) {
        let status = Status::from_telemetry(&self.namespace, t);
        let time = seconds(t.header.time_ns);
        self.now_s = self.now_s.max(time);
        self.joints = status.stiffness.len();
        self.joint = self.joint.min(self.joints - 1);
        self.tracking_error
            .push(time, status.tracking_error, self.settings.window_s);
        let keep = self.intervals();
        push_bounded(
            &mut self.jitter_p99,
            status.jitter_us.p99.round() as u64,
            keep,
        );
        let late = self.last_late.map_or(0, |l| t.late_ticks.saturating_sub(l));
        self.last_late = Some(t.late_ticks);
        push_bounded(&mut self.late_per_interval, late, keep);
        self.status = Some(status);
        self.stale = false;
    }

    /// The namespace's nodes: whether a central process is connected.
    pub(crate) fn on_nodes(&mut self, nodes: &[NodeInfo]) {
        self.central = Some(
            nodes
                .iter()
                .any(|n| n.name == CENTRAL_NODE && n.state == NodeLiveness::Alive),
        );
    }

    /// No telemetry for a while: the board may have stopped (it may come back).
    pub(crate) fn on_silence(&mut self) {
        self.stale = true;
    }

    /// The mode as the banner says it, e.g. "SAFE HOLD" or "FAULT: joint-limit".
    pub(crate) fn banner(&self) -> String {
        let Some(s) = &self.status else {
            return format!("NO BOARD in namespace \"{}\" (waiting)", self.namespace);
        };
        let mode = match s.mode.as_str() {
            "running" => "RUNNING".to_string(),
            // A central process between trials: the board idles until its next reset.
            "idle" if self.central == Some(true) => {
                format!("IDLE: BETWEEN TRIALS ({CENTRAL_NODE} connected)")
            }
            // Holding only when the board says so: a board that freezes its plant while idle
            // reports no stiffness.
            "idle" if s.stiffness.iter().any(|k| *k > 0.0) => {
                "IDLE: HOLDING POSTURE (no central process)".to_string()
            }
            "idle" => "IDLE: PLANT FROZEN (no central process)".to_string(),
            "safe-hold" => "SAFE HOLD (no valid command)".to_string(),
            _ => format!("FAULT: {}", s.fault),
        };
        if self.stale {
            format!("{mode} (board silent)")
        } else {
            mode
        }
    }

    /// The action a key asks for.
    pub(crate) fn on_key(&mut self, key: Key) -> Action {
        let set = self.settings;
        let joint = self.joint;
        let pulse = |sign: f64| {
            let mut torque = [0.0; MAX_JOINTS];
            torque[joint] = sign * set.pulse_torque;
            Action::Send {
                label: format!(
                    "pulse {:+.2} N m, joint {}, {:.0} ms",
                    torque[joint],
                    joint + 1,
                    set.pulse_duration * 1e3
                ),
                requests: vec![Request::Pulse {
                    torque,
                    duration: set.pulse_duration,
                }],
            }
        };
        match key {
            Key::Char('q') | Key::Esc | Key::CtrlC => Action::Quit,
            Key::Char('p' | '+') => pulse(1.0),
            Key::Char('P' | '-') => pulse(-1.0),
            Key::Char(c @ '1'..='9') => {
                let j = c as usize - '1' as usize;
                if j < self.joints {
                    self.joint = j;
                }
                Action::None
            }
            Key::Char('f') => {
                let on = self.status.as_ref().is_some_and(|s| s.field_beta != 0.0);
                let beta = if on { 0.0 } else { set.field_beta };
                Action::Send {
                    label: format!("field β {beta} N/m"),
                    requests: vec![Request::Field { beta }],
                }
            }
            Key::Char('r') => self.reset(),
            _ => Action::None,
        }
    }

    /// `r`: clears the plots and takes the disturbances away (no load, the configured noise, and
    /// the field off when it is on). The trial itself is the central process's to reset: the
    /// monitor publishes disturbances only (docs/PROTOCOL.md, ports by role).
    fn reset(&mut self) -> Action {
        for s in [
            &mut self.q,
            &mut self.stiffness,
            &mut self.tau,
            &mut self.tau_ext,
        ] {
            s.iter_mut().for_each(Series::clear);
        }
        self.tracking_error.clear();
        self.jitter_p99.clear();
        self.late_per_interval.clear();
        let mut requests = vec![
            Request::Load {
                torque: [0.0; MAX_JOINTS],
            },
            Request::Noise { factor: 1.0 },
        ];
        if self.status.as_ref().is_some_and(|s| s.field_beta != 0.0) {
            requests.push(Request::Field { beta: 0.0 });
        }
        Action::Send {
            label: "reset: plots cleared, load 0, noise ×1, field off".into(),
            requests,
        }
    }

    /// An action's requests were sent: counts pulses.
    pub(crate) fn on_sent(&mut self, requests: &[Request]) {
        let pulses = requests
            .iter()
            .filter(|r| matches!(r, Request::Pulse { .. }))
            .count();
        self.pulses_sent += pulses as u64;
    }

    /// The board's answer to a request the monitor sent (`Err`: why it was not applied).
    pub(crate) fn on_answer(
        &mut self,
        label: &str,
        request: &Request,
        answer: Result<Ack, OperatorError>,
    ) {
        let line = match answer {
            Ok(a) => {
                if matches!(request, Request::Pulse { .. }) {
                    self.pulses_acked += 1;
                }
                format!("{label}: applied, tick {} ({:.0} µs)", a.tick, a.latency_us)
            }
            Err(e) => format!("{label}: NOT applied: {e}"),
        };
        push_bounded(&mut self.log, line, LOG_LINES);
    }
}

fn push_bounded<T>(v: &mut VecDeque<T>, x: T, keep: usize) {
    v.push_back(x);
    while v.len() > keep {
        v.pop_front();
    }
}

#[cfg(test)]
mod tests;
