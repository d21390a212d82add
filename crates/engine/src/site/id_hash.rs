//! Salted hashes of transmitter ids in site files: how a site's ids are hashed, hashing a
//! site's ids before it ships, and the matcher an engine on a hashed site uses (see
//! [`crate::radio::Salt`]).

use super::error::invalid;
use super::schema::RadioFile;
use super::{Site, SiteError};
use crate::radio::{RadioMap, Salt, ScanHasher, HASH_HEX_DIGITS, ID_HASH_SCHEME, ID_HASH_VERSION};

/// How a site's transmitter ids are hashed: [`ID_HASH_SCHEME`] version [`ID_HASH_VERSION`]
/// (the only one this build reads), and the salt check that tells the right salt.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IdHashing {
    salt_check: String,
}

impl IdHashing {
    /// HMAC-SHA256(salt, `waymark salt check`), 128 bits as 32 lower-case hex digits.
    pub fn salt_check(&self) -> &str {
        &self.salt_check
    }
}

impl Site {
    /// The same site with every transmitter id replaced by its hash under `salt`
    /// ([`Salt::hash`]) and the salt check recorded, ready to ship without raw MAC addresses.
    /// Engines on it need the same salt ([`EngineConfig::site_salt`](crate::EngineConfig::site_salt)).
    pub fn hashed(&self, salt: &Salt) -> Result<Site, SiteError> {
        if self.id_hashing.is_some() {
            return Err(invalid("radio.id_hash", "the site's transmitter ids are hashed already"));
        }
        let radio = &self.radio;
        let ids = radio.transmitters().iter().map(|id| salt.hash(id)).collect();
        let map = RadioMap::new(
            radio.model(),
            radio.clip_dbm(),
            radio.unheard(),
            ids,
            radio.state_count(),
            radio.fingerprints(),
        )
        .and_then(|map| map.with_shared_radios(radio.shared_radios().to_vec()))
        .map_err(|m| invalid("radio.transmitters", m))?;
        Ok(Site {
            radio: std::sync::Arc::new(map),
            id_hashing: Some(IdHashing { salt_check: salt.check_value() }),
            ..self.clone()
        })
    }

    /// What an engine on this site matches scans with: `None` for raw ids, a [`ScanHasher`]
    /// for hashed ones. Fails when the ids are hashed and `salt` is missing or is not the one
    /// they were hashed with. A salt given for a site with raw ids is not needed and is
    /// ignored (with a log warning).
    pub fn scan_hasher(&self, salt: Option<&Salt>) -> Result<Option<ScanHasher>, SiteError> {
        match (&self.id_hashing, salt) {
            (None, None) => Ok(None),
            (None, Some(_)) => {
                log::warn!("a salt was given, but the site's transmitter ids are not hashed: it is not used");
                Ok(None)
            }
            (Some(_), None) => Err(SiteError::SaltRequired),
            (Some(h), Some(salt)) if salt.matches_check(&h.salt_check) => {
                Ok(Some(ScanHasher::new(salt.clone())))
            }
            (Some(_), Some(_)) => Err(SiteError::WrongSalt),
        }
    }
}

/// The file's id hashing, checked against its transmitters: with `id_hash`, every id must be
/// hashed; without, none may be.
pub(super) fn id_hashing(radio: &RadioFile) -> Result<Option<IdHashing>, SiteError> {
    let hashing = match &radio.id_hash {
        None => None,
        Some(h) if h.scheme != ID_HASH_SCHEME || h.version != ID_HASH_VERSION => {
            return Err(SiteError::UnsupportedIdHash { scheme: h.scheme.clone(), version: h.version })
        }
        Some(h) => {
            let check = h.salt_check.to_ascii_lowercase();
            if check.len() != HASH_HEX_DIGITS || !check.bytes().all(|c| c.is_ascii_hexdigit()) {
                return Err(invalid(
                    "radio.id_hash.salt_check",
                    format!("must be {HASH_HEX_DIGITS} hex digits"),
                ));
            }
            Some(IdHashing { salt_check: check })
        }
    };
    if let Some(k) = radio.transmitters.iter().position(|id| id.is_hashed() != hashing.is_some()) {
        let message = if hashing.is_some() {
            "a raw id in a site whose ids are hashed (radio.id_hash)"
        } else {
            "a hashed id needs radio.id_hash (the scheme and the salt check)"
        };
        return Err(invalid(format!("radio.transmitters[{k}]"), message));
    }
    Ok(hashing)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radio::TransmitterId;
    use crate::site::file::tests::{err, GOOD};

    const SALT: &str = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

    #[test]
    fn hashed_site_holds_no_raw_id_and_round_trips() {
        let salt = Salt::from_hex(SALT).unwrap();
        let raw = Site::from_json(GOOD.as_bytes()).unwrap();
        assert!(raw.id_hashing().is_none());
        assert!(!raw.to_json().contains("id_hash"), "raw files are written as before");
        let hashed = raw.hashed(&salt).unwrap();
        let text = hashed.to_json();
        assert!(!text.contains("00:11:22") && !text.contains("bssid"), "{text}");
        assert!(
            text.contains(r#""id_hash":{"scheme":"hmac-sha256-128","version":1,"salt_check":"#),
            "{text}"
        );
        let again = Site::from_json(text.as_bytes()).unwrap();
        assert_eq!(again.to_json(), text);
        assert_eq!(again.radio().transmitters(), &[salt.hash(&raw.radio().transmitters()[0])]);
        assert_eq!(again.id_hashing().unwrap().salt_check(), salt.check_value());
        let fingerprints =
            |s: &Site| s.radio().fingerprints().map(|(a, b, g)| (a, b, g.mean_dbm)).collect::<Vec<_>>();
        assert_eq!(fingerprints(&again), fingerprints(&raw));
        assert!(matches!(hashed.hashed(&salt), Err(SiteError::Invalid { .. })), "hashed twice");
        let pseudo = hashed.with_pseudo_states(1.0);
        assert!(pseudo.states().len() > hashed.states().len());
        assert_eq!(pseudo.id_hashing(), hashed.id_hashing(), "pseudo states keep the hashing");
    }

    #[test]
    fn the_salt_must_be_the_sites() {
        let salt = Salt::from_hex(SALT).unwrap();
        let other = Salt::new([9u8; 16]).unwrap();
        let raw = Site::from_json(GOOD.as_bytes()).unwrap();
        let hashed = raw.hashed(&salt).unwrap();
        assert!(matches!(hashed.scan_hasher(Some(&salt)), Ok(Some(_))));
        assert_eq!(hashed.scan_hasher(None).unwrap_err(), SiteError::SaltRequired);
        assert_eq!(hashed.scan_hasher(Some(&other)).unwrap_err(), SiteError::WrongSalt);
        assert!(matches!(raw.scan_hasher(Some(&salt)), Ok(None)), "a salt for raw ids is ignored");
        assert!(matches!(raw.scan_hasher(None), Ok(None)));
        for e in [SiteError::SaltRequired, SiteError::WrongSalt] {
            assert!(!e.to_string().contains(SALT), "{e}");
        }
    }

    #[test]
    fn hashed_files_are_checked() {
        let salt = Salt::from_hex(SALT).unwrap();
        let text = Site::from_json(GOOD.as_bytes()).unwrap().hashed(&salt).unwrap().to_json();
        let check = salt.check_value();
        let version = text.replace("\"version\":1", "\"version\":2");
        assert!(matches!(err(&version), SiteError::UnsupportedIdHash { version: 2, .. }));
        let scheme = text.replace("hmac-sha256-128", "hmac-sha3");
        assert!(matches!(err(&scheme), SiteError::UnsupportedIdHash { .. }));
        let hashed_id = salt.hash(&TransmitterId::wifi("00:11:22:33:44:55").unwrap());
        let TransmitterId::HashedWifi { hash } = &hashed_id else { panic!("{hashed_id:?}") };
        let cases = [
            (text.replace(&check, "abc"), "radio.id_hash.salt_check"),
            (
                text.replace(
                    &format!("{{\"hashed_wifi\":{{\"hash\":\"{hash}\"}}}}"),
                    r#"{"wifi":{"bssid":"00:11:22:33:44:55"}}"#,
                ),
                "radio.transmitters[0]",
            ),
            (
                GOOD.replace(
                    r#"{"wifi": {"bssid": "00:11:22:33:44:55"}}"#,
                    &format!(r#"{{"hashed_wifi": {{"hash": "{hash}"}}}}"#),
                ),
                "radio.transmitters[0]",
            ),
            (text.replace(hash, "xyz"), "radio.transmitters[0]"),
            (text.replace("\"salt_check\"", "\"salt\""), "radio.id_hash"),
        ];
        for (text, path) in cases {
            match err(&text) {
                SiteError::Invalid { path: p, message } => {
                    assert!(p.starts_with(path), "expected {path}, got {p}: {message}")
                }
                other => panic!("expected Invalid at {path}, got {other:?}"),
            }
        }
    }
}
