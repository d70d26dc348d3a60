//! `GET /v1/scenes/{id}/events`: the scene's status document as server-sent events.
//!
//! Guarantees: the first event is the current status; another follows every change (changes
//! that happen faster than the client reads are coalesced, never queued without bound); the
//! last event carries a terminal state (`done`, `failed`, `cancelled`) and then the stream
//! ends. Keep-alive comments flow every 15 s. Event streams count against `max_streams`;
//! when those run out, the stream idle the longest may be shed (`idle`): it ends with a
//! `shed` event that asks the client to reconnect after [`SHED_RETRY_MS`].

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::Extension;
use axum::extract::{Path, State};
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::Stream;
use tokio::sync::watch;

use super::clients::Client;
use super::error::{ApiResult, ErrorBody};
use super::jobs::Live;
use super::state::{Shared, StreamGuard, lookup, status_of};

/// The reconnection delay a shed stream asks of its client (`retry:`).
const SHED_RETRY_MS: u64 = 30_000;

struct Events {
    st: Shared,
    reg: super::idle::Registration,
    live: Arc<Live>,
    rx: watch::Receiver<u64>,
    shutdown: watch::Receiver<bool>,
    first: bool,
    done: bool,
    seq: u64,
    _guard: StreamGuard,
}

/// Status changes as server-sent events (`event: status`, `data:` the status JSON).
#[utoipa::path(
    get,
    path = "/v1/scenes/{id}/events",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses(
        (status = 200, description = "text/event-stream of `status` events, each with a SceneStatus JSON; ends after a terminal state, or with a `shed` event (and `retry:`) when the server closes an idle stream to free a slot", content_type = "text/event-stream"),
        (status = 404, description = "Unknown id", body = ErrorBody),
        (status = 429, description = "Too many open streams", body = ErrorBody),
    )
)]
pub(crate) async fn get_events(
    State(st): State<Shared>,
    Path(id): Path<String>,
    client: Option<Extension<Client>>,
) -> ApiResult<Sse<impl Stream<Item = Result<Event, Infallible>>>> {
    let live = lookup(&st, &id).await?;
    let guard = StreamGuard::open(&st, client.map(|Extension(c)| c)).await?;
    let events = Events {
        reg: st.idle_streams.register(),
        rx: live.subscribe(),
        shutdown: st.shutdown.clone(),
        _guard: guard,
        st,
        live,
        first: true,
        done: false,
        seq: 0,
    };
    let stream = futures_util::stream::unfold(events, |mut e| async move {
        if e.done {
            return None;
        }
        if !e.first {
            tokio::select! {
                r = e.rx.changed() => {
                    if r.is_err() {
                        return None;
                    }
                }
                _ = e.shutdown.changed() => return None,
                _ = e.reg.shed.notified() => {
                    e.done = true;
                    let event = Event::default()
                        .event("shed")
                        .retry(Duration::from_millis(SHED_RETRY_MS))
                        .data("this idle stream was closed to free a slot for another client; reconnect later");
                    return Some((Ok(event), e));
                }
            }
        }
        e.first = false;
        e.rx.borrow_and_update();
        let status = status_of(&e.st, &e.live);
        e.done = status.state.is_terminal();
        e.reg.touch();
        e.seq += 1;
        let event = Event::default()
            .event("status")
            .id(e.seq.to_string())
            .json_data(&status)
            .unwrap_or_else(|_| Event::default().event("status").data("{}"));
        Some((Ok(event), e))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}
