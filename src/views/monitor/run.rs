//! The terminal loop of the live view: raw mode and the alternate screen (restored on exit, on
//! error, on a panic and on a termination signal), the board's states and telemetry into the
//! [`App`], the keys into [`Action`]s, and what an action sends done on a thread of its own through
//! [`inject`] (which takes the disturbance publisher only while it sends), so the view never
//! waits for an acknowledgement.

use super::{Action, App, Key, Settings, draw};
use crate::views::operator::{OperatorError, Request, inject};
use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use vic_rt::transport::MonitorPorts;

/// Why the live view stopped with an error.
#[derive(Debug, thiserror::Error)]
pub(crate) enum MonitorError {
    #[error(transparent)]
    Operator(#[from] OperatorError),
    #[error("the terminal: {0}")]
    Terminal(#[from] std::io::Error),
}

/// Frames per second of the view (the states are drained every frame; the state buffer holds
/// 128 ms of them).
const FRAME: Duration = Duration::from_millis(50);
/// Telemetry comes every 100 ms; this long without it, the banner says the board is silent.
const SILENT: Duration = Duration::from_secs(1);
/// How long a sent disturbance waits for the board's acknowledgement.
const ACK_TIMEOUT: Duration = Duration::from_secs(2);

/// How often the view lists the namespace's nodes.
const NODES_EVERY: Duration = Duration::from_secs(1);

/// The board's answer to one request, from the sending thread.
type Answer = (
    String,
    Request,
    Result<crate::views::operator::Ack, OperatorError>,
);

/// Runs the live view of the board in `namespace` until `q`, Esc, Ctrl-C or `stop` is set.
pub(crate) fn run(
    namespace: &str,
    settings: Settings,
    stop: &AtomicBool,
) -> Result<(), MonitorError> {
    let ports = MonitorPorts::open(namespace).map_err(OperatorError::from)?;
    // Raw mode and the alternate screen; ratatui's panic hook restores them before the message.
    let mut terminal = ratatui::try_init()?;
    let result = view(&mut terminal, &ports, namespace, settings, stop);
    let restored = ratatui::try_restore();
    result?;
    Ok(restored?)
}

fn view(
    terminal: &mut ratatui::DefaultTerminal,
    ports: &MonitorPorts,
    namespace: &str,
    settings: Settings,
    stop: &AtomicBool,
) -> Result<(), MonitorError> {
    let mut app = App::new(namespace, settings);
    let (tx, rx) = mpsc::channel::<Answer>();
    let mut last_telemetry = Instant::now();
    let mut last_nodes: Option<Instant> = None;
    let mut senders = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        // Who is connected, once a second: the banner tells a board between trials from one
        // without a central process.
        if last_nodes.is_none_or(|t| t.elapsed() >= NODES_EVERY) {
            if let Ok(nodes) = vic_rt::transport::list_nodes(namespace) {
                app.on_nodes(&nodes);
            }
            last_nodes = Some(Instant::now());
        }
        ports.drain_states(|s| app.on_state(s));
        if let Some(t) = ports.latest_telemetry() {
            app.on_telemetry(&t);
            last_telemetry = Instant::now();
        } else if last_telemetry.elapsed() > SILENT {
            app.on_silence();
        }
        while let Ok((label, request, answer)) = rx.try_recv() {
            app.on_answer(&label, &request, answer);
        }
        terminal.draw(|f| draw(f, &app))?;
        if !event::poll(FRAME)? {
            continue;
        }
        let Some(key) = key_of(event::read()?) else {
            continue;
        };
        match app.on_key(key) {
            Action::Quit => break,
            Action::None => {}
            Action::Send { label, requests } => {
                app.on_sent(&requests);
                senders.push(send(namespace, label, requests, tx.clone()));
                senders.retain(|h: &std::thread::JoinHandle<()>| !h.is_finished());
            }
        }
    }
    // Each sender's node leaves the namespace cleanly (each waits at most ACK_TIMEOUT).
    senders.into_iter().for_each(|h| drop(h.join()));
    Ok(())
}

/// Sends `requests` in order on a thread of its own, each answer back through `tx`.
fn send(
    namespace: &str,
    label: String,
    requests: Vec<Request>,
    tx: mpsc::Sender<Answer>,
) -> std::thread::JoinHandle<()> {
    let namespace = namespace.to_string();
    std::thread::spawn(move || {
        for r in requests {
            let answer = inject(&namespace, r, ACK_TIMEOUT);
            if tx.send((label.clone(), r, answer)).is_err() {
                return; // the view has quit
            }
        }
    })
}

/// The key of a terminal event (presses only; Ctrl-C arrives as a key in raw mode).
fn key_of(e: Event) -> Option<Key> {
    let Event::Key(k) = e else { return None };
    if k.kind != KeyEventKind::Press {
        return None;
    }
    match k.code {
        KeyCode::Char('c') if k.modifiers.contains(KeyModifiers::CONTROL) => Some(Key::CtrlC),
        KeyCode::Char(c) => Some(Key::Char(c)),
        KeyCode::Esc => Some(Key::Esc),
        _ => None,
    }
}
