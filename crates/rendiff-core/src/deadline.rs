//! A time limit the core's loops honour without being killed: the tool's
//! `check --timeout` bounds the core's own renders as it bounds external
//! renderers, which are separate processes it can kill.

use std::time::Instant;

/// True once `deadline` has passed. The core's loops call it once per tile,
/// row or pixel and skip the rest of their work when it is true (the caller
/// then discards the partial frame). `None` never expires.
pub fn past(deadline: Option<Instant>) -> bool {
    deadline.is_some_and(|d| Instant::now() >= d)
}
