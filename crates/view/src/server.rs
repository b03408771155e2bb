//! The viewer's web server (axum, as the study's): the page and its scripts (embedded from
//! `web/view/`), the run's manifest, its mesh, and the run's files by index.
//!
//! Routes: `GET /` (the page), `/view.js`, `/splats.js`, `/sort-worker.js`, `/view.css`,
//! `GET /api/run` (the [`Manifest`](crate::run::Manifest) as JSON), `GET /api/mesh` (a
//! surface run's [`MeshBuffers`](crate::run::MeshBuffers)), `GET /files/{index}` (a file
//! the manifest names, with Range requests for video seeking). Nothing else of the disk is
//! reachable.

use std::net::SocketAddr;
use std::sync::Arc;

use axum::Router;
use axum::extract::{Path, Request, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use tower::ServiceExt;
use tower_http::services::ServeFile;

use crate::error::{Result, ViewError};
use crate::run::Run;

/// The page's files: route, content type, contents.
const ASSETS: [(&str, &str, &str); 5] = [
    (
        "/",
        "text/html; charset=utf-8",
        include_str!("../../../web/view/index.html"),
    ),
    (
        "/view.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/view/view.js"),
    ),
    (
        "/splats.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/view/splats.js"),
    ),
    (
        "/sort-worker.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../web/view/sort-worker.js"),
    ),
    (
        "/view.css",
        "text/css; charset=utf-8",
        include_str!("../../../web/view/view.css"),
    ),
];

struct AppState {
    run: Run,
    manifest_json: String,
}

type Shared = Arc<AppState>;

fn not_found(what: String) -> Response {
    (StatusCode::NOT_FOUND, what).into_response()
}

async fn file(State(app): State<Shared>, Path(index): Path<usize>, request: Request) -> Response {
    let Some(path) = app.run.files.get(index) else {
        return not_found(format!("no file {index}"));
    };
    match ServeFile::new(path).oneshot(request).await {
        Ok(r) => r.map(axum::body::Body::new).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

fn router(app: Shared) -> Router {
    let mut r = Router::new();
    for (route, content_type, body) in ASSETS {
        r = r.route(
            route,
            get(move || async move {
                (
                    [
                        (header::CONTENT_TYPE, content_type),
                        (header::CACHE_CONTROL, "no-store"),
                    ],
                    body,
                )
            }),
        );
    }
    r.route(
        "/api/run",
        get(|State(app): State<Shared>| async move {
            (
                [(header::CONTENT_TYPE, "application/json")],
                app.manifest_json.clone(),
            )
        }),
    )
    .route(
        "/api/mesh",
        get(|State(app): State<Shared>| async move {
            match &app.run.mesh {
                Some(m) => (
                    [(header::CONTENT_TYPE, "application/octet-stream")],
                    m.0.clone(),
                )
                    .into_response(),
                None => not_found("this run has no mesh".into()),
            }
        }),
    )
    .route("/files/{index}", get(file))
    .with_state(app)
}

/// Serves `run` until Ctrl-C; `on_listen` receives the bound address (port 0 picks one).
pub fn serve(run: Run, addr: SocketAddr, on_listen: impl FnOnce(SocketAddr)) -> Result<()> {
    let manifest_json =
        serde_json::to_string(&run.manifest).map_err(|e| ViewError::Server(e.to_string()))?;
    let app = Arc::new(AppState { run, manifest_json });
    let failed = |what: String| move |e: std::io::Error| ViewError::Server(format!("{what}: {e}"));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
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
                .map_err(|e| ViewError::Server(e.to_string()))?,
        );
        axum::serve(listener, router(app))
            .with_graceful_shutdown(async {
                let _ = tokio::signal::ctrl_c().await;
            })
            .await
            .map_err(failed("server".into()))
    })
}
