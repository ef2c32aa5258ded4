//! The tests with real processes, shared memory and clocks: the board, the planner and the
//! operator tools as daemons, the transport, recording, the bridge, the Python client. Apart
//! from the offline tests so that the solver's long tests never compete with a real-time loop.

mod common;

// The allocation tests count this thread's allocations only, so the other tests running in
// parallel do not disturb them.
#[global_allocator]
static GLOBAL: common::alloc::Counting = common::alloc::Counting;

mod bench;
mod board_alloc;
mod board_limits;
mod board_lost;
mod bridge;
mod bridge_auth;
mod bridge_clock;
mod bridge_hostile;
mod central_refusal;
mod clients;
mod daemon_logs;
mod demo_distributed;
mod faults;
mod flood;
mod foxglove_view;
mod interleaved_senders;
mod monitor_tui;
mod namespaces;
mod observers;
mod other_user;
mod protocol_doc;
mod python_client;
mod python_owner_only;
mod realtime;
mod record;
mod record_crash;
mod record_mcap;
mod relay_alloc;
mod squatting;
mod status_counts;
mod status_nodes;
