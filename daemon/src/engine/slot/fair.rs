//! The queue in front of the chip's single blocking slot, fair between
//! clients: each client has its own first-in-first-out line, and the lines
//! take turns. A script that queues two hundred SDO reads delays another
//! client's single read by at most one transaction per busy client, not by
//! two hundred (the vendor driver's one global mutex gives no such promise).
//!
//! Clients are numbered by the front ends (`master::Call`); requests
//! made outside any client share line 0. The daemon's own work
//! ([`super::client::DAEMON_CLIENT`]) has a line of its own that takes
//! every other turn while clients are busy.

use std::collections::VecDeque;

use super::client::DAEMON_CLIENT;
use super::request::Job;

/// Per-client lines served round-robin.
#[derive(Debug, Default)]
pub(crate) struct FairQueue {
    /// (client, its line). Lines are kept when empty, so a client's next
    /// request does not allocate; there are as many as clients seen.
    lines: Vec<(u64, VecDeque<Job>)>,
    /// The line whose turn is next.
    turn: usize,
    len: usize,
    /// The daemon's own line, and whether it goes next.
    daemon: VecDeque<Job>,
    daemon_next: bool,
}

impl FairQueue {
    /// Lines kept when they are empty; beyond this, empty lines are dropped.
    const KEEP_LINES: usize = 64;

    /// Queues a job at the end of its client's line.
    pub(crate) fn push(&mut self, job: Job) {
        let client = job.client;
        self.len += 1;
        if client == DAEMON_CLIENT {
            self.daemon.push_back(job);
            return;
        }
        if let Some((_, line)) = self.lines.iter_mut().find(|(c, _)| *c == client) {
            line.push_back(job);
            return;
        }
        if self.lines.len() >= Self::KEEP_LINES {
            self.forget_empty_lines();
        }
        let mut line = VecDeque::with_capacity(8);
        line.push_back(job);
        self.lines.push((client, line));
    }

    /// The next job: the head of the next non-empty line in turn.
    pub(crate) fn pop(&mut self) -> Option<Job> {
        if self.len == 0 {
            return None;
        }
        let clients_waiting = self.len > self.daemon.len();
        if !self.daemon.is_empty() && (self.daemon_next || !clients_waiting) {
            self.daemon_next = false;
            self.len -= 1;
            return self.daemon.pop_front();
        }
        self.daemon_next = true;
        for _ in 0..self.lines.len() {
            let i = self.turn % self.lines.len();
            self.turn = i + 1;
            if let Some(job) = self.lines[i].1.pop_front() {
                self.len -= 1;
                return Some(job);
            }
        }
        None
    }

    /// Jobs waiting.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Whether no job waits.
    pub(crate) fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Every waiting job, in no particular order (for failing them all).
    pub(crate) fn drain(&mut self) -> impl Iterator<Item = Job> + '_ {
        self.len = 0;
        self.daemon.drain(..).chain(self.lines.iter_mut().flat_map(|(_, line)| line.drain(..)))
    }

    fn forget_empty_lines(&mut self) {
        self.lines.retain(|(_, line)| !line.is_empty());
        self.turn = 0;
    }
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::*;
    use crate::engine::slot::SlotRequest;

    fn job(slave: u8) -> Job {
        let (reply, _) = tokio::sync::oneshot::channel();
        let request = SlotRequest::SlaveInfo { slave, item: ecmxf_wire::payload::slave_info::SlaveInfoCode::Name };
        Job { request, deadline: Instant::now(), reply, progress: None, client: 0, buffer: Vec::new() }
    }

    fn slave(j: Job) -> u8 {
        match j.request {
            SlotRequest::SlaveInfo { slave, .. } => slave,
            _ => unreachable!(),
        }
    }

    #[test]
    fn clients_take_turns_and_each_keeps_its_order() {
        let mut q = FairQueue::default();
        for n in 0..5 {
            q.push(Job { client: 1, ..job(10 + n) });
        }
        q.push(Job { client: 2, ..job(20) });
        q.push(Job { client: 2, ..job(21) });
        q.push(Job { client: 3, ..job(30) });
        assert_eq!(q.len(), 8);
        let order: Vec<u8> = std::iter::from_fn(|| q.pop()).map(slave).collect();
        assert_eq!(order, [10, 20, 30, 11, 21, 12, 13, 14]);
        assert!(q.is_empty());
        // A client arriving later waits for at most one turn of each busy line.
        for n in 0..3 {
            q.push(Job { client: 1, ..job(10 + n) });
        }
        assert_eq!(slave(q.pop().unwrap()), 10);
        q.push(Job { client: 4, ..job(40) });
        let order: Vec<u8> = std::iter::from_fn(|| q.pop()).map(slave).collect();
        assert_eq!(order, [40, 11, 12]);
    }

    #[test]
    fn the_daemon_takes_every_other_turn_however_many_clients_wait() {
        let mut q = FairQueue::default();
        for client in [1, 3, 5] {
            for n in 0..3 {
                q.push(Job { client, ..job(client as u8 * 10 + n) });
            }
        }
        for n in 0..4 {
            q.push(Job { client: DAEMON_CLIENT, ..job(200 + n) });
        }
        let order: Vec<u8> = std::iter::from_fn(|| q.pop()).map(slave).collect();
        // With clients waiting, every other job is the daemon's until its
        // line is empty; alone, its jobs run back to back.
        assert_eq!(order, [10, 200, 30, 201, 50, 202, 11, 203, 31, 51, 12, 32, 52]);
        q.push(Job { client: DAEMON_CLIENT, ..job(1) });
        q.push(Job { client: DAEMON_CLIENT, ..job(2) });
        assert_eq!(q.len(), 2);
        assert_eq!(q.drain().count(), 2);
        assert!(q.pop().is_none());
    }

    #[test]
    fn many_clients_over_time_do_not_grow_the_lines_forever() {
        let mut q = FairQueue::default();
        for client in 0..1000 {
            q.push(Job { client, ..job(1) });
            assert!(q.pop().is_some());
        }
        assert!(q.lines.len() <= FairQueue::KEEP_LINES + 1);
        q.push(Job { client: 7, ..job(7) });
        q.push(Job { client: 8, ..job(8) });
        assert_eq!(q.drain().count(), 2);
        assert!(q.is_empty() && q.pop().is_none());
    }
}
