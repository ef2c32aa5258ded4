//! A hidden helper for `scripts/soak.sh` across the bridge (`SOAK_BRIDGE=1`): every `EVERY_MS` it
//! puts one malformed message straight onto the Zenoh link, past both iceoryx2 namespaces, on the
//! key the board-side bridge takes command slices from. In turn: 7 bytes (not the size of a
//! slice) and a slice-sized message of another protocol version. The board-side bridge must
//! count each (`malformed_size`, `malformed_version`) and forward none. At the end it prints one
//! JSON line with how many of each it sent.
//!
//! cargo run --release --features zenoh --example link_junk -- LINK_NAME ENDPOINT [SECONDS] [EVERY_MS]

use std::time::{Duration, Instant};
use vic_rt::bridge::{key, wire};
use vic_rt::transport::{CommandSlice, Header, PROTOCOL_VERSION, monotonic_ns};
use zenoh::Wait;

/// Zenoh's errors as anyhow's (they are boxed without `Sized`, so `?` alone does not convert).
fn z<T>(r: zenoh::Result<T>) -> anyhow::Result<T> {
    r.map_err(|e| anyhow::anyhow!("zenoh: {e}"))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(link), Some(endpoint)) = (args.first(), args.get(1)) else {
        eprintln!("usage: link_junk LINK_NAME ENDPOINT [SECONDS=60] [EVERY_MS=1000]");
        std::process::exit(2);
    };
    let seconds: f64 = args.get(2).map_or(Ok(60.0), |s| s.parse())?;
    let every = Duration::from_millis(args.get(3).map_or(Ok(1000), |s| s.parse())?);

    let mut config = zenoh::Config::default();
    z(config.insert_json5(
        "connect/endpoints",
        &serde_json::json!([endpoint]).to_string(),
    ))?;
    z(config.insert_json5("scouting/multicast/enabled", "false"))?;
    let session = z(zenoh::open(config).wait())?;
    let publisher = z(session.declare_publisher(key::<CommandSlice>(link)).wait())?;
    // Let the bridge's subscription reach this session before the first put.
    std::thread::sleep(Duration::from_millis(500));

    let wrong_version = {
        let mut c = CommandSlice {
            header: Header::new(1, monotonic_ns()),
            ..Default::default()
        };
        c.header.version = PROTOCOL_VERSION + 100;
        wire::encode(&c).to_vec()
    };
    let (mut size, mut version) = (0u64, 0u64);
    let t0 = Instant::now();
    let mut next = t0;
    let mut n = 0u64;
    while t0.elapsed().as_secs_f64() < seconds {
        next += every;
        if n.is_multiple_of(2) {
            z(publisher.put(vec![0xAB_u8; 7]).wait())?;
            size += 1;
        } else {
            z(publisher.put(wrong_version.clone()).wait())?;
            version += 1;
        }
        n += 1;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    println!(
        "{}",
        serde_json::json!({ "malformed_size": size, "malformed_version": version })
    );
    let _ = session.close().wait();
    Ok(())
}
