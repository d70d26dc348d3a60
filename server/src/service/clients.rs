//! Per-client limits: uploads being read and streams open at once, per remote address, so that
//! one address (a few trickling uploads, hundreds of idle event streams) cannot hold every slot
//! of the server-wide limits (`max_uploads`, `max_streams`) — nginx's `limit_conn` per
//! `$binary_remote_addr`, applied to the two kinds of long requests.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};

use super::error::{ApiError, ApiResult};

/// The remote address of a request's connection (added by the accept loop).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Client(pub IpAddr);

/// What a slot is held for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Kind {
    Upload,
    Stream,
}

/// Slots held, per (address, kind).
#[derive(Default)]
pub(crate) struct ClientSlots {
    held: Mutex<HashMap<(IpAddr, Kind), u32>>,
}

/// One held slot; given back on drop.
pub(crate) struct ClientSlot {
    slots: Arc<ClientSlots>,
    key: (IpAddr, Kind),
}

impl ClientSlots {
    /// A slot of `kind` for the request's client (none to hold for a request without an
    /// address), or 429 when the client already holds `max`.
    pub(crate) fn acquire(
        self: &Arc<Self>,
        client: Option<Client>,
        kind: Kind,
        max: u32,
    ) -> ApiResult<Option<ClientSlot>> {
        let Some(Client(ip)) = client else {
            return Ok(None);
        };
        self.try_acquire(ip, kind, max).map(Some).ok_or_else(|| {
            ApiError::too_many(match kind {
                Kind::Upload => format!(
                    "{max} uploads are in progress from your address, the most this server \
                     allows one client; retry when one has finished"
                ),
                Kind::Stream => format!(
                    "{max} streams are open from your address, the most this server allows \
                     one client; close one or retry later"
                ),
            })
        })
    }

    /// A slot of `kind` for `ip`, unless it already holds `max`.
    pub(crate) fn try_acquire(
        self: &Arc<Self>,
        ip: IpAddr,
        kind: Kind,
        max: u32,
    ) -> Option<ClientSlot> {
        let mut held = self.held.lock().unwrap_or_else(|p| p.into_inner());
        let n = held.entry((ip, kind)).or_insert(0);
        if *n >= max {
            return None;
        }
        *n += 1;
        Some(ClientSlot {
            slots: self.clone(),
            key: (ip, kind),
        })
    }
}

impl Drop for ClientSlot {
    fn drop(&mut self) {
        let mut held = self.slots.held.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = held.get_mut(&self.key) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                held.remove(&self.key);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_are_per_address_and_kind_and_come_back_on_drop() {
        let s = Arc::new(ClientSlots::default());
        let a: IpAddr = [127, 0, 0, 1].into();
        let b: IpAddr = [127, 0, 0, 2].into();
        let one = s.try_acquire(a, Kind::Upload, 2).expect("first");
        let two = s.try_acquire(a, Kind::Upload, 2).expect("second");
        assert!(
            s.try_acquire(a, Kind::Upload, 2).is_none(),
            "a third from a"
        );
        assert!(
            s.try_acquire(b, Kind::Upload, 2).is_some(),
            "another address"
        );
        assert!(s.try_acquire(a, Kind::Stream, 2).is_some(), "another kind");
        drop(one);
        let three = s.try_acquire(a, Kind::Upload, 2).expect("given back");
        drop((two, three));
        assert!(s.held.lock().unwrap_or_else(|p| p.into_inner()).is_empty());
    }
}
