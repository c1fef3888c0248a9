//! The web side: axum routes, the token check and the live stream (server-sent events).

use crate::poller::{self, Poller, Request};
use crate::{ConsoleConfig, ConsoleError};
use axum::Router;
use axum::extract::{Request as HttpRequest, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use tokio_stream::StreamExt;
use tokio_stream::wrappers::WatchStream;

/// The page: HTML + JS in one file, embedded in the binary (no build step).
pub const PAGE: &str = include_str!("console.html");

struct AppState {
    poller: std::sync::Mutex<std::sync::mpsc::Sender<Request>>,
    status: tokio::sync::watch::Receiver<Arc<str>>,
    token: Option<String>,
}

/// Constant-time comparison, so the token cannot be guessed byte by byte from response times.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// The token from `Authorization: Bearer T`, or from `?token=T` (EventSource and a browser's
/// first page load cannot set headers).
fn presented_token<'a>(headers: &'a HeaderMap, query: Option<&'a str>) -> Option<&'a str> {
    if let Some(v) = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
    {
        return Some(v);
    }
    query?.split('&').find_map(|kv| kv.strip_prefix("token="))
}

async fn check_token(State(st): State<Arc<AppState>>, req: HttpRequest, next: Next) -> Response {
    if let Some(want) = &st.token {
        let ok = presented_token(req.headers(), req.uri().query())
            .is_some_and(|t| same(t.as_bytes(), want.as_bytes()));
        if !ok {
            return (StatusCode::UNAUTHORIZED, "console token required\n").into_response();
        }
    }
    next.run(req).await
}

async fn page() -> impl IntoResponse {
    ([(header::CACHE_CONTROL, "no-store")], Html(PAGE))
}

async fn api_status(State(st): State<Arc<AppState>>) -> Response {
    let s = st.status.borrow().clone();
    ([(header::CONTENT_TYPE, "application/json")], s.to_string()).into_response()
}

async fn api_trips(State(st): State<Arc<AppState>>) -> Response {
    let (tx, rx) = tokio::sync::oneshot::channel();
    let sent = st
        .poller
        .lock()
        .map(|p| p.send(Request::Trips(tx)).is_ok())
        .unwrap_or(false);
    match (sent, rx.await) {
        (true, Ok(trips)) => axum::Json(trips).into_response(),
        _ => (StatusCode::SERVICE_UNAVAILABLE, "iceoryx2 poller stopped\n").into_response(),
    }
}

async fn api_stop(State(st): State<Arc<AppState>>) -> Response {
    let (tx, rx) = tokio::sync::oneshot::channel();
    let sent = st
        .poller
        .lock()
        .map(|p| p.send(Request::Stop(tx)).is_ok())
        .unwrap_or(false);
    match (sent, rx.await) {
        (true, Ok(Ok(seq))) => {
            axum::Json(serde_json::json!({ "stop": "published", "sequence": seq })).into_response()
        }
        (true, Ok(Err(e))) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("stop NOT published: {e}\n"),
        )
            .into_response(),
        _ => (StatusCode::SERVICE_UNAVAILABLE, "iceoryx2 poller stopped\n").into_response(),
    }
}

/// The start button: the ride goes to motion-core's control socket (as `crs ride start`)
/// only if every pre-ride check passes at the moment the request arrives.
async fn api_ride_start(State(st): State<Arc<AppState>>) -> Response {
    let (tx, rx) = tokio::sync::oneshot::channel();
    let sent = st
        .poller
        .lock()
        .map(|p| p.send(Request::StartRide(tx)).is_ok())
        .unwrap_or(false);
    let (socket, ride) = match (sent, rx.await) {
        (true, Ok(Ok(go))) => go,
        (true, Ok(Err(failed))) => {
            return (
                StatusCode::CONFLICT,
                format!(
                    "ride NOT started: pre-ride checks fail: {}\n",
                    failed.join("; ")
                ),
            )
                .into_response();
        }
        _ => return (StatusCode::SERVICE_UNAVAILABLE, "iceoryx2 poller stopped\n").into_response(),
    };
    let name = ride.name().to_string();
    let req = ride.start_request();
    let sent =
        tokio::task::spawn_blocking(move || crs_ipc::ride_control::request(&socket, &req)).await;
    use crs_ipc::ride_control::ClientError;
    match sent {
        Ok(Ok(msg)) => {
            tracing::warn!(ride = %name, "ride started from the operator console: {msg}");
            axum::Json(serde_json::json!({ "ride": "started", "message": msg })).into_response()
        }
        Ok(Err(ClientError::Refused(why))) => {
            tracing::warn!(ride = %name, "ride from the operator console refused: {why}");
            (
                StatusCode::CONFLICT,
                format!("ride refused by motion-core: {why}\n"),
            )
                .into_response()
        }
        Ok(Err(e)) => (
            StatusCode::SERVICE_UNAVAILABLE,
            format!("ride NOT started: {e}\n"),
        )
            .into_response(),
        Err(_) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            "ride NOT started: the request's task failed\n",
        )
            .into_response(),
    }
}

async fn api_events(
    State(st): State<Arc<AppState>>,
) -> Sse<impl tokio_stream::Stream<Item = Result<Event, Infallible>>> {
    // Every status update of the poller (25 Hz) becomes one event; a slow client skips to the
    // newest (watch keeps only the latest value), so clients never queue up.
    let stream =
        WatchStream::new(st.status.clone()).map(|s| Ok(Event::default().event("status").data(&*s)));
    Sse::new(stream).keep_alive(KeepAlive::default())
}

/// The router over a running poller.
pub fn router(p: &Poller, token: Option<String>) -> Router {
    let st = Arc::new(AppState {
        poller: std::sync::Mutex::new(p.requests.clone()),
        status: p.status.clone(),
        token,
    });
    Router::new()
        .route("/", get(page))
        .route("/api/status", get(api_status))
        .route("/api/trips", get(api_trips))
        .route("/api/events", get(api_events))
        .route("/api/stop", post(api_stop))
        .route("/api/ride/start", post(api_ride_start))
        .layer(middleware::from_fn_with_state(st.clone(), check_token))
        .with_state(st)
}

/// Serves until `shutdown` completes; `ready` is called with the bound address.
pub async fn serve(
    cfg: ConsoleConfig,
    ready: impl FnOnce(SocketAddr),
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> Result<(), ConsoleError> {
    cfg.validate()?;
    let poller = poller::start(
        &cfg.prefix,
        cfg.platform.clone(),
        cfg.plan.clone(),
        cfg.avoid_cpu,
        cfg.rides.clone(),
    )?;
    let app = router(&poller, cfg.token.clone());
    let listener = tokio::net::TcpListener::bind(cfg.addr)
        .await
        .map_err(|source| ConsoleError::Bind {
            addr: cfg.addr,
            source,
        })?;
    let addr = listener.local_addr()?;
    tracing::info!(%addr, prefix = %cfg.prefix, "operator console listening");
    ready(addr);
    // Live streams never end by themselves: on shutdown stop the poller first, which ends
    // them, so the graceful shutdown does not wait for the browsers forever.
    let stop = poller.stop_flag();
    axum::serve(listener, app)
        .with_graceful_shutdown(async move {
            shutdown.await;
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
        })
        .await?;
    drop(poller);
    Ok(())
}
