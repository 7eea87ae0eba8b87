//! [`Roles`]: what a key may do, and what each endpoint needs ([`Need`]).

use axum::http::Method;

/// A set of roles, as a key's line in the keys file names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Roles(u8);

impl Roles {
    /// `POST /stabilize`, `/jobs`: its own tenant's jobs.
    pub const SUBMIT: Roles = Roles(1);
    /// `GET /live`.
    pub const VIEW: Roles = Roles(2);
    /// `GET /live/ingest`.
    pub const PUBLISH: Roles = Roles(4);
    /// Every tenant's jobs, `/metrics`.
    pub const ADMIN: Roles = Roles(8);
    pub const ALL: Roles = Roles(15);
    const NAMES: [(&'static str, Roles); 4] = [
        ("submit", Roles::SUBMIT),
        ("view", Roles::VIEW),
        ("publish", Roles::PUBLISH),
        ("admin", Roles::ADMIN),
    ];

    /// A comma list of `submit`, `view`, `publish`, `admin`.
    pub fn parse(list: &str) -> Result<Roles, String> {
        let mut roles = Roles(0);
        for name in list.split(',') {
            let name = name.trim();
            match Self::NAMES.iter().find(|(n, _)| *n == name) {
                Some((_, r)) => roles.0 |= r.0,
                None => {
                    return Err(format!(
                        "unknown role {:?} in {list:?} (allowed: a comma list of submit, view, publish, admin)",
                        name.chars().take(40).collect::<String>()
                    ))
                }
            }
        }
        Ok(roles)
    }

    pub fn has(self, r: Roles) -> bool {
        self.0 & r.0 == r.0
    }

    /// The names, as the keys file writes them.
    pub fn names(self) -> Vec<&'static str> {
        Self::NAMES
            .iter()
            .filter(|(_, r)| self.has(*r))
            .map(|(n, _)| *n)
            .collect()
    }
}

impl std::fmt::Display for Roles {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.names().join(","))
    }
}

/// What an endpoint needs of its caller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Need {
    /// `/healthz` and the page's files: anyone.
    Public,
    /// Any valid key (`/openapi.json`).
    AnyKey,
    /// `submit` or `admin` (`/stabilize`, `/jobs...`).
    Jobs,
    /// `view` (`/live`).
    View,
    /// `publish` (`/live/ingest`).
    Publish,
    /// `view` or `publish` (`POST /live/ticket`: a ticket for either socket).
    Ticket,
    /// `admin` (`/metrics`).
    Admin,
}

impl Need {
    /// What `method path` needs. Unknown paths are public: they are the
    /// page's files or a 404.
    pub fn of(method: &Method, path: &str) -> Need {
        let _ = method;
        match path {
            "/healthz" => Need::Public,
            "/openapi.json" => Need::AnyKey,
            "/stabilize" | "/jobs" => Need::Jobs,
            p if p.starts_with("/jobs/") => Need::Jobs,
            "/live" => Need::View,
            "/live/ingest" => Need::Publish,
            "/live/ticket" => Need::Ticket,
            "/metrics" => Need::Admin,
            _ => Need::Public,
        }
    }

    /// Whether `roles` meet it.
    pub fn met_by(self, roles: Roles) -> bool {
        match self {
            Need::Public | Need::AnyKey => true,
            Need::Jobs => roles.has(Roles::SUBMIT) || roles.has(Roles::ADMIN),
            Need::View => roles.has(Roles::VIEW),
            Need::Publish => roles.has(Roles::PUBLISH),
            Need::Ticket => roles.has(Roles::VIEW) || roles.has(Roles::PUBLISH),
            Need::Admin => roles.has(Roles::ADMIN),
        }
    }

    /// The roles to name in a 403.
    pub fn describe(self) -> &'static str {
        match self {
            Need::Public | Need::AnyKey => "none",
            Need::Jobs => "submit (or admin)",
            Need::View => "view",
            Need::Publish => "publish",
            Need::Ticket => "view or publish",
            Need::Admin => "admin",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_parse_and_print_as_the_file_writes_them() {
        let r = Roles::parse("view, submit").unwrap();
        assert_eq!(r.to_string(), "submit,view");
        assert!(Roles::parse("submit,").is_err());
        assert!(Roles::parse("Admin").is_err());
        assert_eq!(
            Roles::parse("submit,view,publish,admin").unwrap(),
            Roles::ALL
        );
    }

    #[test]
    fn each_endpoint_needs_its_role() {
        let get = Method::GET;
        let sub = Roles::SUBMIT;
        assert!(Need::of(&get, "/jobs/abc/output").met_by(sub));
        assert!(Need::of(&get, "/jobs").met_by(Roles::ADMIN));
        assert!(!Need::of(&get, "/jobs").met_by(Roles::VIEW));
        assert!(!Need::of(&get, "/live").met_by(sub));
        assert!(Need::of(&get, "/live").met_by(Roles::VIEW));
        assert!(!Need::of(&get, "/live/ingest").met_by(Roles::VIEW));
        assert!(!Need::of(&get, "/live/ingest").met_by(Roles::ADMIN));
        assert!(!Need::of(&get, "/metrics").met_by(Roles::ALL.minus_admin()));
        assert_eq!(Need::of(&get, "/healthz"), Need::Public);
        assert_eq!(Need::of(&get, "/index.html"), Need::Public);
        assert_eq!(Need::of(&get, "/jobsx"), Need::Public);
    }

    impl Roles {
        fn minus_admin(self) -> Roles {
            Roles(self.0 & !Roles::ADMIN.0)
        }
    }
}
