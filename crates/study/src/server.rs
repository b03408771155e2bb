//! The study web server (axum): the page (embedded from `web/study/`), a small JSON API, and
//! the videos served from disk. Every answer is committed to SQLite before the reply, so a
//! crash or a reload loses nothing and a participant resumes where they left off.
//!
//! API (JSON):
//! * `POST /api/participants` `{"participant": optional id}` → state (joins or resumes)
//! * `GET  /api/participants/{id}` → state
//! * `POST /api/participants/{id}/answers` `{"index": n, "answers": {"Q1": "left", ...}}` → state
//! * `GET  /media/{id}/{index}/{left|right}` → the video of that side of that trial
//!
//! A state is `{participant, answered, total, done, title, questions, trial?}` where `trial` is
//! `{index, left: {url, kind}, right: {url, kind}}` (`kind`: `video` or `image`). Errors are
//! `{"error": "..."}` with status 400 (malformed), 404 (unknown) or 409 (out of order).

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};

use axum::extract::{Path, Request, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use tower::ServiceExt;
use tower_http::services::ServeFile;

use crate::config::StudyConfig;
use crate::error::{Result, StudyError};
use crate::store::{Store, SubmitError, Trial};

const INDEX_HTML: &str = include_str!("../../../web/study/index.html");
const STUDY_JS: &str = include_str!("../../../web/study/study.js");
const STUDY_CSS: &str = include_str!("../../../web/study/study.css");

struct AppState {
    config: StudyConfig,
    store: Mutex<Store>,
    counter: std::sync::atomic::AtomicU64,
}

type Shared = Arc<AppState>;

/// An API error: status and a one-line message.
struct ApiError(StatusCode, String);

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.0, Json(serde_json::json!({ "error": self.1 }))).into_response()
    }
}

impl From<SubmitError> for ApiError {
    fn from(e: SubmitError) -> Self {
        let status = match &e {
            SubmitError::UnknownParticipant(_) => StatusCode::NOT_FOUND,
            SubmitError::Invalid(_) => StatusCode::BAD_REQUEST,
            SubmitError::Conflict(_) => StatusCode::CONFLICT,
            SubmitError::Db(_) => StatusCode::INTERNAL_SERVER_ERROR,
        };
        ApiError(status, e.to_string())
    }
}

fn db_error(e: impl std::fmt::Display) -> ApiError {
    ApiError(StatusCode::INTERNAL_SERVER_ERROR, format!("database: {e}"))
}

/// Participant ids: 1–64 characters of letters, digits, `-` and `_`.
fn valid_participant(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 64
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

fn media_kind(path: &std::path::Path) -> &'static str {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ["gif", "png", "jpg", "jpeg", "webp"].contains(&ext.as_str()) {
        "image"
    } else {
        "video"
    }
}

/// The file of `method` in the trial's scene. A stored plan can name a scene or method that
/// the configuration no longer has (it was edited after participants joined): a clear error.
fn video_path(app: &AppState, trial: &Trial, method: &str) -> Result<std::path::PathBuf, ApiError> {
    app.config.videos.get(&trial.scene).and_then(|m| m.get(method)).cloned().ok_or_else(|| {
        ApiError(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("the stored plan names scene {:?}, method {method:?}, which the study configuration no longer has", trial.scene),
        )
    })
}

fn state_json(app: &AppState, participant: &str) -> Result<serde_json::Value, ApiError> {
    let (answered, total, next) = app
        .store
        .lock()
        .expect("store lock")
        .progress(participant)
        .map_err(db_error)?;
    let trial = match next {
        Some(t) => {
            let side = |s: &str, method: &str| -> Result<serde_json::Value, ApiError> {
                let path = video_path(app, &t, method)?;
                Ok(
                    serde_json::json!({ "url": format!("/media/{participant}/{}/{s}", t.index), "kind": media_kind(&path) }),
                )
            };
            Some(
                serde_json::json!({ "index": t.index, "left": side("left", &t.left)?, "right": side("right", &t.right)? }),
            )
        }
        None => None,
    };
    Ok(serde_json::json!({
        "participant": participant,
        "answered": answered,
        "total": total,
        "done": trial.is_none(),
        "title": app.config.title,
        "questions": app.config.questions,
        "trial": trial,
    }))
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JoinRequest {
    participant: Option<String>,
}

async fn join(
    State(app): State<Shared>,
    body: Option<Json<JoinRequest>>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let requested = body.and_then(|Json(b)| b.participant);
    let id = match requested {
        Some(id) if valid_participant(&id) => id,
        Some(id) => {
            return Err(ApiError(
                StatusCode::BAD_REQUEST,
                format!("participant id {id:?} must be 1-64 letters, digits, '-' or '_'"),
            ));
        }
        None => {
            // Not a random choice that affects results (the plan is seeded by the id): a unique
            // id from the clock and a counter.
            let n = app
                .counter
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let t = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos())
                .unwrap_or(0);
            format!("p{:x}{:04x}", t as u64, n & 0xffff)
        }
    };
    let app2 = app.clone();
    let id2 = id.clone();
    tokio::task::spawn_blocking(move || {
        app2.store
            .lock()
            .expect("store lock")
            .join(&app2.config, &id2)
            .map_err(db_error)?;
        state_json(&app2, &id2)
    })
    .await
    .map_err(db_error)?
    .map(Json)
}

async fn get_state(
    State(app): State<Shared>,
    Path(id): Path<String>,
) -> Result<Json<serde_json::Value>, ApiError> {
    tokio::task::spawn_blocking(move || {
        if !valid_participant(&id)
            || !app
                .store
                .lock()
                .expect("store lock")
                .exists(&id)
                .map_err(db_error)?
        {
            return Err(ApiError(
                StatusCode::NOT_FOUND,
                format!("unknown participant {id:?}"),
            ));
        }
        state_json(&app, &id)
    })
    .await
    .map_err(db_error)?
    .map(Json)
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct AnswerRequest {
    index: usize,
    answers: std::collections::BTreeMap<String, String>,
}

async fn answer(
    State(app): State<Shared>,
    Path(id): Path<String>,
    body: Result<Json<AnswerRequest>, axum::extract::rejection::JsonRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let Json(req) = body.map_err(|e| {
        ApiError(
            StatusCode::BAD_REQUEST,
            format!("malformed answer: {}", e.body_text()),
        )
    })?;
    if !valid_participant(&id) {
        return Err(ApiError(
            StatusCode::NOT_FOUND,
            format!("unknown participant {id:?}"),
        ));
    }
    tokio::task::spawn_blocking(move || {
        app.store
            .lock()
            .expect("store lock")
            .submit(&app.config, &id, req.index, &req.answers)?;
        state_json(&app, &id)
    })
    .await
    .map_err(db_error)?
    .map(Json)
}

async fn media(
    State(app): State<Shared>,
    Path((id, index, side)): Path<(String, usize, String)>,
    request: Request,
) -> Result<Response, ApiError> {
    if side != "left" && side != "right" {
        return Err(ApiError(
            StatusCode::NOT_FOUND,
            "side must be left or right".into(),
        ));
    }
    let app2 = app.clone();
    let id2 = id.clone();
    let trial = tokio::task::spawn_blocking(move || {
        app2.store.lock().expect("store lock").trial(&id2, index)
    })
    .await
    .map_err(db_error)?
    .map_err(db_error)?
    .ok_or_else(|| {
        ApiError(
            StatusCode::NOT_FOUND,
            format!("no trial {index} for participant {id:?}"),
        )
    })?;
    let method = if side == "left" {
        &trial.left
    } else {
        &trial.right
    };
    let path = video_path(&app, &trial, method)?;
    // ServeFile handles Range requests (video seeking) and content types.
    let response = ServeFile::new(path)
        .oneshot(request)
        .await
        .map_err(|e| ApiError(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?;
    let (mut parts, body) = response.into_parts();
    parts.headers.insert(
        header::CACHE_CONTROL,
        header::HeaderValue::from_static("no-store"),
    );
    Ok(Response::from_parts(parts, axum::body::Body::new(body)))
}

fn static_text(content_type: &'static str, body: &'static str) -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-store"),
        ],
        body,
    )
}

/// The router, for the server and for tests.
fn router(app: Shared) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { static_text("text/html; charset=utf-8", INDEX_HTML) }),
        )
        .route(
            "/study.js",
            get(|| async { static_text("text/javascript; charset=utf-8", STUDY_JS) }),
        )
        .route(
            "/study.css",
            get(|| async { static_text("text/css; charset=utf-8", STUDY_CSS) }),
        )
        .route("/api/participants", post(join))
        .route("/api/participants/{id}", get(get_state))
        .route("/api/participants/{id}/answers", post(answer))
        .route("/media/{id}/{index}/{side}", get(media))
        .with_state(app)
}

/// Serves the study until Ctrl-C; `on_listen` receives the bound address (port 0 picks one).
pub fn serve(
    config: StudyConfig,
    addr: SocketAddr,
    on_listen: impl FnOnce(SocketAddr),
) -> Result<()> {
    let store = Store::open(&config.database)?;
    let app = Arc::new(AppState {
        config,
        store: Mutex::new(store),
        counter: Default::default(),
    });
    let failed = |what: String| move |e: std::io::Error| StudyError::Server(format!("{what}: {e}"));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(failed("tokio runtime".into()))?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(failed(format!("cannot listen on {addr}")))?;
        on_listen(
            listener
                .local_addr()
                .map_err(|e| StudyError::Server(e.to_string()))?,
        );
        axum::serve(listener, router(app))
            .with_graceful_shutdown(async {
                let _ = tokio::signal::ctrl_c().await;
            })
            .await
            .map_err(failed("server".into()))
    })
}
