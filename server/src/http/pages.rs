//! The participant pages: server-rendered HTML that needs no script and no build step.
//!
//! - `GET /contest`: the contest home ([`home`]): tracks, metrics, how to take part, data, rules;
//! - `GET|POST /team/login`, `POST /team/logout`: a team token opens a server-side session;
//! - `GET /team`: the team's submissions and quota left ([`team`]);
//! - `GET /submissions/{id}`: one submission, for its team or the organiser ([`submission`]);
//! - `GET /leaderboard/{track}/{split}/{id}`: a leaderboard entry's public summary;
//! - `GET /favicon.ico`: 204, no icon (the browser asks for it on its own).
//!
//! Policy: a page that needs a team takes the token once (the login form), which opens a session
//! whose id the `kitchen_r_team` cookie holds (`crate::service::sessions`); the organiser's console cookie opens submission pages too. Cookies
//! and CSRF follow [`super::session`]. Another team's submission answers 404, the same as one
//! that does not exist, so a page never reveals which ids are taken. A leaderboard entry's page
//! shows only what the leaderboard row shows, for ranked (and baseline) rows only.

mod api_docs;
mod home;
mod layout;
mod submission;
mod team;
pub(super) mod words;

use axum::Router;
use axum::extract::{Form, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use axum::routing::{get, post};
use kitchen_r_core::dataset::Split;
use maud::{Markup, html};
use serde::Deserialize;

use super::extract::{ClientAddr, PathArg, QueryArgs};
use super::queries::LoginQuery;
use super::session;
use super::viewer::{TEAM_COOKIE, Who, session_caller, who};
use crate::error::ServiceError;
use crate::leaderboard::Track;
use crate::service::sessions::{Login, Role};
use crate::service::{AppState, Caller};
use kitchen_r_core::GraspMode;
use kitchen_r_core::observations::ObservationTrack;
use layout::Viewer;

pub(super) fn routes() -> Router<AppState> {
    Router::new()
        .route("/contest", get(contest))
        .route("/api/docs", get(api_docs::page))
        .route("/team", get(team_page))
        .route("/team/login", get(login_form).post(login))
        .route("/team/logout", post(logout))
        .route("/submissions/{id}", get(submission_page))
        .route(
            "/submissions/{id}/episodes/{episode_key}/path.png",
            get(episode_plot),
        )
        .route(
            "/submissions/{id}/episodes/{episode_key}/video.mp4",
            get(super::video::page_video),
        )
        .route("/leaderboard/{track}/{split}/{id}", get(entry_page))
        .route("/favicon.ico", get(favicon))
}

/// Browsers ask every site for `/favicon.ico` by themselves; the pages have no icon. A 204
/// (kept for a day) instead of a 404 keeps that request out of the browser console, where a
/// real error would otherwise hide among them (tests/browser/check_pages.py fails on any).
async fn favicon() -> Response {
    axum::response::IntoResponse::into_response((
        StatusCode::NO_CONTENT,
        [(axum::http::header::CACHE_CONTROL, "public, max-age=86400")],
    ))
}

/// Render `body` in the frame for `who`, with the logout form's CSRF field.
fn respond(
    headers: &HeaderMap,
    who: &Who,
    status: StatusCode,
    title: &str,
    refresh: Option<u32>,
    body: Markup,
) -> Response {
    let csrf = session::csrf(headers, TEAM_COOKIE);
    let viewer = match who {
        Who::Nobody => Viewer::Nobody,
        Who::Team(t) => Viewer::Team {
            name: &t.name,
            csrf: &csrf.field,
        },
        Who::Organiser(_) => Viewer::Organiser,
    };
    session::html_with(status, layout::page(title, &viewer, refresh, body), &csrf)
}

fn not_found(headers: &HeaderMap, who: &Who, what: &str) -> Response {
    let body = html! {
        p { "There is no " (what) " here, or it is not yours to see." }
        p { a href="/team" { "Your team page" } }
    };
    respond(headers, who, StatusCode::NOT_FOUND, "Not found", None, body)
}

/// 303 to the login form, coming back to `next` afterwards.
fn to_login(next: &str) -> Response {
    session::see_other(&format!("/team/login?next={next}"), &[])
}

async fn contest(
    State(s): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let who = who(&s, caller, &headers).await?;
    Ok(respond(
        &headers,
        &who,
        StatusCode::OK,
        "Kitchen-R contest",
        None,
        home::body(&s),
    ))
}

async fn team_page(
    State(s): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let who = who(&s, caller, &headers).await?;
    let team = match &who {
        Who::Team(t) => t,
        Who::Organiser(_) => {
            let body = html! {
                p { "The organiser has no team. Teams' runs are on the " a href="/admin" { "console" } "." }
            };
            return Ok(respond(&headers, &who, StatusCode::OK, "Team page", None, body));
        }
        Who::Nobody => return Ok(to_login("/team")),
    };
    let quota = s.team_quota(team).await?;
    let subs = s.team_submissions(team).await?;
    let title = format!("Team {}", team.name);
    Ok(respond(
        &headers,
        &who,
        StatusCode::OK,
        &title,
        None,
        team::body(&quota, &subs),
    ))
}

fn login_page(headers: &HeaderMap, status: StatusCode, message: Option<&str>, next: &str) -> Response {
    let csrf = session::csrf(headers, TEAM_COOKIE);
    let page = layout::page(
        "Team login",
        &Viewer::Nobody,
        None,
        team::login(message, &csrf.field, next),
    );
    session::html_with(status, page, &csrf)
}

async fn login_form(headers: HeaderMap, QueryArgs(q): QueryArgs<LoginQuery>) -> Response {
    let next = session::local_path(q.next.as_deref()).unwrap_or("/team");
    login_page(&headers, StatusCode::OK, None, next)
}

#[derive(Debug, Deserialize)]
struct LoginForm {
    token: Option<String>,
    csrf: Option<String>,
    next: Option<String>,
}

/// `POST /team/login` (form `token`, `csrf`, `next`): a team token opens a session.
async fn login(
    State(s): State<AppState>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    form: Result<Form<LoginForm>, axum::extract::rejection::FormRejection>,
) -> Result<Response, ServiceError> {
    let form = form.map(|Form(f)| f).unwrap_or(LoginForm {
        token: None,
        csrf: None,
        next: None,
    });
    let next = session::local_path(form.next.as_deref()).unwrap_or("/team");
    if !session::csrf_ok(&headers, TEAM_COOKIE, form.csrf.as_deref()) {
        return Ok(login_page(
            &headers,
            StatusCode::FORBIDDEN,
            Some(session::CSRF_REFUSED),
            next,
        ));
    }
    let token = form.token.as_deref().unwrap_or("");
    match s.log_in(Role::Team, token, client).await? {
        Login::Opened {
            cookie,
            max_age_s,
            caller,
        } => {
            if let Caller::Team(t) = caller {
                tracing::info!(team = %t.name, "team logged in to the pages");
            }
            let c = session::session_cookie(TEAM_COOKIE, &cookie, max_age_s, session::https(&headers));
            Ok(session::see_other(next, &[c]))
        }
        Login::Refused(message) => Ok(login_page(
            &headers,
            StatusCode::UNAUTHORIZED,
            Some(message),
            next,
        )),
        Login::Throttled { retry_after_s } => {
            let message = session::throttled_message(retry_after_s);
            let page = login_page(&headers, StatusCode::TOO_MANY_REQUESTS, Some(&message), next);
            Ok(session::with_retry_after(page, retry_after_s))
        }
    }
}

#[derive(Debug, Deserialize)]
struct CsrfForm {
    csrf: Option<String>,
}

/// `POST /team/logout` (form `csrf`): end the session and drop the team cookie.
async fn logout(
    State(s): State<AppState>,
    headers: HeaderMap,
    form: Result<Form<CsrfForm>, axum::extract::rejection::FormRejection>,
) -> Result<Response, ServiceError> {
    let sent = form.ok().and_then(|Form(f)| f.csrf);
    if !session::csrf_ok(&headers, TEAM_COOKIE, sent.as_deref()) {
        return Ok(login_page(
            &headers,
            StatusCode::FORBIDDEN,
            Some(session::CSRF_REFUSED),
            "/team",
        ));
    }
    if let Some(id) = session::session_id(&headers, TEAM_COOKIE) {
        s.log_out(id).await?;
    }
    let gone = session::set_cookie(TEAM_COOKIE, "", Some(0), session::https(&headers));
    Ok(session::see_other("/contest", &[gone]))
}

/// An episode's path plot for the page's `<img>` (the API's `plot_url` takes a bearer token,
/// which an image request cannot send): the same checks, by the page's session.
async fn episode_plot(
    State(s): State<AppState>,
    PathArg((id, key)): PathArg<(String, String)>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let not_found = || ServiceError::not_found(format!("a plot of episode {key:?} of submission {id}"));
    let caller = session_caller(&s, caller, &headers)
        .await?
        .ok_or_else(not_found)?;
    let sub = id.parse::<i64>().map_err(|_| not_found())?;
    let png = s.episode_plot(&caller, sub, &key).await?;
    Ok(axum::response::IntoResponse::into_response((
        [(axum::http::header::CONTENT_TYPE, "image/png")],
        png,
    )))
}

async fn submission_page(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let who = who(&s, caller, &headers).await?;
    let Ok(id) = id.parse::<i64>() else {
        return Ok(not_found(&headers, &who, "such submission"));
    };
    let caller = match &who {
        Who::Team(t) => Caller::Team(t.clone()),
        Who::Organiser(o) => Caller::Organiser(*o),
        Who::Nobody => return Ok(to_login(&format!("/submissions/{id}"))),
    };
    let mut view = match s.get_submission(&caller, id).await {
        Ok(v) => v,
        Err(ServiceError::NotFound { .. }) => return Ok(not_found(&headers, &who, "such submission")),
        Err(e) => return Err(e),
    };
    // Showing an episode asks for its video: queue the renders the page would show.
    if s.render_shown(&caller, id, &view).await? {
        view = s.get_submission(&caller, id).await?;
    }
    let running = submission::running(&view);
    let eta = (view.latest_run.as_ref())
        .and_then(|r| r.evaluation.as_ref())
        .and_then(|e| e.eta.clone());
    let title = format!("Submission {id}");
    let refresh = match (running, submission::rendering(&view)) {
        (true, _) => Some(submission::REFRESH_S),
        (false, true) => Some(submission::RENDER_REFRESH_S),
        (false, false) => None,
    };
    let body = submission::body(&view, eta.as_ref());
    Ok(respond(&headers, &who, StatusCode::OK, &title, refresh, body))
}

async fn entry_page(
    State(s): State<AppState>,
    PathArg((track, split, id)): PathArg<(String, String, String)>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let who = who(&s, caller, &headers).await?;
    let parsed = (
        track.parse::<Track>().ok().filter(|_| !track.is_empty()),
        split.parse::<Split>().ok(),
        id.parse::<i64>().ok(),
    );
    let (Some(track), Some(split), Some(id)) = parsed else {
        return Ok(not_found(&headers, &who, "such leaderboard entry"));
    };
    // A submission is on one observation track's and one grasp mode's board only; planning has
    // just the standard board and no grasp mode.
    let mut found = None;
    let modes: &[Option<GraspMode>] = match track {
        Track::Planning => &[None],
        _ => &[Some(GraspMode::Abstract), Some(GraspMode::Physical)],
    };
    'boards: for observations in ObservationTrack::ALL {
        if track == Track::Planning && observations == ObservationTrack::Privileged {
            break;
        }
        for &grasp in modes {
            let board = s.board(track, observations, grasp, split).await?;
            found = board.rows.into_iter().find(|r| r.submission_id == id);
            if found.is_some() {
                break 'boards;
            }
        }
    }
    let Some(row) = found.as_ref() else {
        return Ok(not_found(&headers, &who, "such leaderboard entry"));
    };
    let title = format!("{} on the {} leaderboard", row.team, track.as_str());
    let body = team::entry(track, split.as_str(), row);
    Ok(respond(&headers, &who, StatusCode::OK, &title, None, body))
}

#[cfg(test)]
mod login_throttle_tests;
#[cfg(test)]
mod session_tests;
#[cfg(test)]
mod tests;
