//! The participant pages end to end: the real `kitchen-r serve` process, a team that submits a
//! dev plan file over the API, then a browser-like client (no redirects followed, cookies kept
//! by hand the way a browser keeps them) that logs in through the form and reads the team and
//! submission pages.

use std::collections::BTreeMap;
use std::time::Duration;

use reqwest::header::{CONTENT_TYPE, COOKIE, LOCATION, SET_COOKIE};
use reqwest::{Response, StatusCode};

use crate::support::*;

/// The cookies a browser would hold for the server.
#[derive(Default)]
struct Jar(BTreeMap<String, String>);

impl Jar {
    fn take(&mut self, r: &Response) {
        for v in r.headers().get_all(SET_COOKIE) {
            let v = v.to_str().unwrap();
            let (name, value) = v.split(';').next().unwrap().split_once('=').unwrap();
            if v.contains("Max-Age=0") {
                self.0.remove(name);
            } else {
                self.0.insert(name.to_string(), value.to_string());
            }
        }
    }

    fn header(&self) -> String {
        let pairs: Vec<String> = self.0.iter().map(|(k, v)| format!("{k}={v}")).collect();
        pairs.join("; ")
    }
}

fn browser() -> reqwest::Client {
    reqwest::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(Duration::from_secs(30))
        .build()
        .unwrap()
}

fn csrf_of(page: &str) -> String {
    let after = page
        .split("name=csrf value=\"")
        .nth(1)
        .expect("a form with a CSRF field");
    after.split('"').next().unwrap().to_string()
}

fn location(r: &Response) -> String {
    r.headers()[LOCATION].to_str().unwrap().to_string()
}

/// GET `path` as the browser; stores its cookies; returns (status, Location or body).
async fn open(server: &Server, jar: &mut Jar, path: &str) -> (StatusCode, String) {
    let r = browser()
        .get(server.url(path))
        .header(COOKIE, jar.header())
        .send()
        .await
        .unwrap();
    jar.take(&r);
    let status = r.status();
    match status {
        StatusCode::SEE_OTHER => (status, location(&r)),
        _ => (status, r.text().await.unwrap()),
    }
}

/// POST a form as the browser; stores its cookies.
async fn send_form(server: &Server, jar: &mut Jar, path: &str, form: String) -> Response {
    let r = browser()
        .post(server.url(path))
        .header(COOKIE, jar.header())
        .header(CONTENT_TYPE, "application/x-www-form-urlencoded")
        .body(form)
        .send()
        .await
        .unwrap();
    jar.take(&r);
    r
}

#[tokio::test]
async fn a_team_logs_in_through_the_form_and_reads_its_team_and_submission_pages() {
    let fx = Fixture::new("[quota]\ndev_per_day = 10\n");
    let server = fx.serve();
    let token = team(&server, "alpha").await;
    let other = team(&server, "beta").await;
    let file: String = dev_plans().iter().map(|(id, p)| line(id, p) + "\n").collect();
    let (status, sub) = submit(&server, Some(&token), "dev", file).await;
    assert_eq!(status, 201, "{sub}");
    let id = sub["id"].as_i64().unwrap();
    let mut jar = Jar::default();

    // The team page sends an anonymous browser to the login form, which comes back to it.
    let (status, to) = open(&server, &mut jar, "/team").await;
    assert_eq!(
        (status, to.as_str()),
        (StatusCode::SEE_OTHER, "/team/login?next=/team")
    );
    let (status, form) = open(&server, &mut jar, &to).await;
    assert_eq!(status, StatusCode::OK);
    assert!(jar.0.contains_key("kitchen_r_csrf"), "the form's nonce cookie");

    // A login without the form's CSRF field is refused; with it, the cookie is set.
    let r = send_form(
        &server,
        &mut jar,
        "/team/login",
        format!("token={token}&next=/team"),
    )
    .await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    assert!(!jar.0.contains_key("kitchen_r_team"));
    let login = format!("token={token}&csrf={}&next=/team", csrf_of(&form));
    let r = send_form(&server, &mut jar, "/team/login", login).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(location(&r), "/team");
    let set: Vec<&str> = r
        .headers()
        .get_all(SET_COOKIE)
        .iter()
        .map(|v| v.to_str().unwrap())
        .collect();
    let session = set.iter().find(|c| c.starts_with("kitchen_r_team=")).unwrap();
    assert!(
        session.contains("HttpOnly") && session.contains("SameSite=Strict"),
        "{session}"
    );

    // The team page: the submission with its EM, and the quota left today.
    let (status, page) = open(&server, &mut jar, "/team").await;
    assert_eq!(status, StatusCode::OK, "{page}");
    assert!(page.contains("Team <b>alpha</b>"), "{page}");
    assert!(
        page.contains(&format!("<a href=\"/submissions/{id}\">{id}</a>")),
        "{page}"
    );
    assert!(page.contains("1.000000"), "{page}");
    assert!(
        page.contains("<td class=\"n\">10</td><td class=\"n\">1</td><td class=\"n\">9</td>"),
        "{page}"
    );
    assert!(!page.contains("<script"), "{page}");

    // The submission page: EM and a row per dev instruction.
    let (status, page) = open(&server, &mut jar, &format!("/submissions/{id}")).await;
    assert_eq!(status, StatusCode::OK, "{page}");
    for needle in [
        "plan file",
        "Per instruction",
        "dev-0001",
        "dev-0003",
        "4 of 4",
        "8 of 8",
    ] {
        assert!(page.contains(needle), "{needle}: {page}");
    }
    assert!(!page.contains("<script"), "{page}");

    // Another team's browser gets a 404, as for an id that does not exist.
    let r = browser()
        .get(server.url(&format!("/submissions/{id}")))
        .bearer_auth(&other)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::NOT_FOUND);

    // Logging out (with the page's CSRF field) ends the session, on the server too: a copy of
    // the cookie taken before (another browser's, a stolen one) opens nothing afterwards.
    let copied = jar.header();
    let (_, team_page) = open(&server, &mut jar, "/team").await;
    let r = send_form(
        &server,
        &mut jar,
        "/team/logout",
        format!("csrf={}", csrf_of(&team_page)),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert!(!jar.0.contains_key("kitchen_r_team"));
    let (status, _) = open(&server, &mut jar, &format!("/submissions/{id}")).await;
    assert_eq!(status, StatusCode::SEE_OTHER);
    let r = browser()
        .get(server.url("/team"))
        .header(COOKIE, copied)
        .send()
        .await
        .unwrap();
    assert_eq!(
        r.status(),
        StatusCode::SEE_OTHER,
        "a logged-out cookie still works"
    );

    // Guessing is throttled per client address (`[sessions]`: 10 failures a minute): the 11th
    // wrong token in a row is answered 429 with Retry-After, whatever its token.
    let (_, form) = open(&server, &mut jar, "/team/login").await;
    let guess = |t: &str| format!("token={t}&csrf={}&next=/team", csrf_of(&form));
    for i in 0..10 {
        let r = send_form(&server, &mut jar, "/team/login", guess(&format!("kr_{i:064}"))).await;
        assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
    }
    let r = send_form(&server, &mut jar, "/team/login", guess(&token)).await;
    assert_eq!(r.status(), StatusCode::TOO_MANY_REQUESTS);
    assert!(r.headers().contains_key("retry-after"));
}
