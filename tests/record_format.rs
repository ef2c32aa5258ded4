//! The recorder's CSV, read back by `vic identify`'s reader: every tick once, gaps marked,
//! non-finite rows kept out of the log columns.

use std::path::PathBuf;
use std::time::Duration;
use vic::studies::identify::read_log;
use vic_rt::record::*;

fn sample(tick: u64) -> Sample {
    Sample {
        tick,
        deadline_ns: 1_000_000 * (tick + 100),
        q: [0.1 * tick as f64, -0.2],
        stiffness: [50.0, 60.0],
        damping: [5.0, 6.0],
        ..Default::default()
    }
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("vic_record_{}_{name}.csv", std::process::id()))
}

/// The `x_tick` and `x_dropped` columns and the gap comments of a file.
fn ticks_and_gaps(text: &str) -> (Vec<u64>, Vec<u64>, Vec<String>) {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| head.iter().position(|h| *h == n).unwrap();
    let (ct, cd) = (col("x_tick"), col("x_dropped"));
    let mut ticks = vec![];
    let mut dropped = vec![];
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        assert_eq!(f.len(), head.len(), "{l}");
        ticks.push(f[ct].parse().unwrap());
        dropped.push(f[cd].parse().unwrap());
    }
    let gaps = text
        .lines()
        .filter(|l| l.starts_with("# gap"))
        .map(String::from)
        .collect();
    (ticks, dropped, gaps)
}

#[test]
fn every_sample_is_written_in_order_and_the_log_reader_reads_the_file() {
    let path = temp("all");
    let mut r = Recorder::start(&path, &RecordOptions::default()).unwrap();
    for t in 1..=3000 {
        assert!(r.producer().push(&sample(t)));
    }
    let s = r.finish().unwrap();
    assert_eq!((s.written, s.dropped, s.gaps), (3000, 0, 0));
    assert_eq!((s.first_tick, s.last_tick), (1, 3000));
    let text = std::fs::read_to_string(&path).unwrap();
    let (ticks, dropped, gaps) = ticks_and_gaps(&text);
    assert_eq!(ticks, (1..=3000).collect::<Vec<u64>>());
    assert!(dropped.iter().all(|d| *d == 0));
    assert!(gaps.is_empty());
    let rows = read_log(text.as_bytes()).unwrap();
    assert_eq!(rows.len(), 3000);
    assert_eq!(rows[9].q, 1.0);
    assert_eq!(rows[9].stiffness, 50.0);
    assert_eq!(rows[9].damping, 5.0);
    assert!((rows[9].t - 0.009).abs() < 1e-12);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn an_overflow_is_marked_in_the_file_with_the_number_of_ticks_dropped() {
    let path = temp("overflow");
    let opts = RecordOptions {
        capacity: 4,
        joints: 1,
        start_paused: true,
        ..Default::default()
    };
    let mut r = Recorder::start(&path, &opts).unwrap();
    // Writer paused: ticks 1–4 fill the queue, 5–10 are dropped.
    let accepted: Vec<bool> = (1..=10).map(|t| r.producer().push(&sample(t))).collect();
    assert_eq!(accepted, [[true; 4].as_slice(), &[false; 6]].concat());
    assert_eq!(r.producer().dropped(), 6);
    r.set_paused(false);
    while r.producer().free_slots() < 4 {
        std::thread::sleep(Duration::from_millis(1));
    }
    // Then 11–12 get through, 13–15 are dropped while paused again, and the run ends.
    assert!(r.producer().push(&sample(11)));
    assert!(r.producer().push(&sample(12)));
    while r.producer().free_slots() < 4 {
        std::thread::sleep(Duration::from_millis(1));
    }
    r.set_paused(true);
    for t in 13..=19 {
        r.producer().push(&sample(t));
    }
    // 13–16 are queued, 17–19 dropped at the end of the run.
    let s = r.finish().unwrap();
    assert_eq!((s.written, s.dropped, s.gaps), (10, 9, 2));
    let text = std::fs::read_to_string(&path).unwrap();
    let (ticks, dropped, gaps) = ticks_and_gaps(&text);
    assert_eq!(ticks, [1, 2, 3, 4, 11, 12, 13, 14, 15, 16]);
    assert_eq!(dropped, [0, 0, 0, 0, 6, 0, 0, 0, 0, 0]);
    assert_eq!(
        gaps,
        [
            "# gap: 6 ticks dropped (ticks 5 to 10): recording queue full",
            "# gap: 3 ticks dropped (ticks 17 to 19): recording queue full"
        ]
    );
    // The gap comment comes right before the first row after the gap.
    let after_gap = text
        .lines()
        .skip_while(|l| !l.starts_with("# gap: 6"))
        .nth(1);
    assert!(after_gap.unwrap().contains(",11,6,"), "{after_gap:?}");
    assert_eq!(read_log(text.as_bytes()).unwrap().len(), 10);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn a_non_finite_row_is_kept_as_a_comment() {
    let path = temp("nan");
    let mut r = Recorder::start(&path, &RecordOptions::default()).unwrap();
    let mut s = sample(1);
    s.q[0] = f64::NAN;
    r.producer().push(&s);
    r.producer().push(&sample(2));
    assert_eq!(r.finish().unwrap().written, 2);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("# non-finite: 0,NaN,"), "{text}");
    assert_eq!(read_log(text.as_bytes()).unwrap().len(), 1);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn the_header_names_the_log_columns_first() {
    assert!(header(1).starts_with(LOG_HEADER));
    assert_eq!(header(1).split(',').count(), 19);
    assert_eq!(header(2).split(',').count(), 29);
    assert!(header(2).ends_with(",x_tau_1,x_tau_ext_1"));
}
