//! Child processes of a run (a board, a planner) that must not outlive it, and the namespace they
//! share: [`Children`] stops them with SIGTERM (so they print their statistics), kills what does
//! not stop within 3 s, and removes the namespace's files, whatever way the run ends.

use std::process::Child;
use std::time::{Duration, Instant};

/// Children and their namespace, cleaned up on drop.
pub struct Children {
    pub namespace: String,
    pub children: Vec<Child>,
}

impl Children {
    pub fn new(namespace: &str) -> Self {
        Children {
            namespace: namespace.to_string(),
            children: Vec::new(),
        }
    }

    /// SIGTERM, then SIGKILL after 3 s; reaps the child.
    pub fn terminate(child: &mut Child) {
        if let Ok(None) = child.try_wait() {
            // SAFETY: kill(2) on the pid of a child we spawned and have not reaped.
            unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
            let t0 = Instant::now();
            while let Ok(None) = child.try_wait() {
                if t0.elapsed() > Duration::from_secs(3) {
                    let _ = child.kill();
                    let _ = child.wait();
                    break;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        for c in &mut self.children {
            Self::terminate(c);
        }
        crate::transport::remove_namespace(&self.namespace);
    }
}
