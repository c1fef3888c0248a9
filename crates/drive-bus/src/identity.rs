//! A node's identity as drives.toml expects it (`identity = { ... }` of a `[[winch]]` or
//! `[[force_sensor]]`): device type 0x1000 and the identity object 0x1018 (vendor, product,
//! revision, serial), plus the manufacturer device name 0x1008 (a string: segmented SDO).
//! drive-io reads every configured value at boot before it writes anything and stops start-up
//! on a mismatch, naming the node, the object, the expected and the found value — as CiA 302's
//! 0x1F84-0x1F88 checks do in a CANopen manager. A wrong or swapped device on a node id is
//! never configured.

use serde::Deserialize;

pub const OD_IDENTITY: u16 = 0x1018;
pub const OD_DEVICE_NAME: u16 = 0x1008;

#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Identity {
    /// 0x1000 (CiA 402 servo: 0x00020192; CiA 404 analog input: 0x00020194).
    #[serde(default)]
    pub device_type: Option<u32>,
    /// 0x1018 sub 1 (the CiA-assigned vendor id).
    #[serde(default)]
    pub vendor_id: Option<u32>,
    /// 0x1018 sub 2.
    #[serde(default)]
    pub product_code: Option<u32>,
    /// 0x1018 sub 3.
    #[serde(default)]
    pub revision: Option<u32>,
    /// 0x1018 sub 4.
    #[serde(default)]
    pub serial: Option<u32>,
    /// 0x1008, compared byte for byte.
    #[serde(default)]
    pub device_name: Option<String>,
}

/// One numeric identity check: object, expected value, the TOML key (for messages).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IdentityCheck {
    pub index: u16,
    pub sub: u8,
    pub expected: u32,
    pub key: &'static str,
}

impl Identity {
    /// The configured numeric checks, device type first.
    pub fn checks(&self) -> Vec<IdentityCheck> {
        [
            (0x1000, 0, self.device_type, "device_type"),
            (OD_IDENTITY, 1, self.vendor_id, "vendor_id"),
            (OD_IDENTITY, 2, self.product_code, "product_code"),
            (OD_IDENTITY, 3, self.revision, "revision"),
            (OD_IDENTITY, 4, self.serial, "serial"),
        ]
        .into_iter()
        .filter_map(|(index, sub, v, key)| {
            v.map(|expected| IdentityCheck {
                index,
                sub,
                expected,
                key,
            })
        })
        .collect()
    }

    /// The TOML key of the check on `(index, sub)`.
    pub fn key_of(index: u16, sub: u8) -> &'static str {
        match (index, sub) {
            (0x1000, 0) => "device_type",
            (OD_IDENTITY, 1) => "vendor_id",
            (OD_IDENTITY, 2) => "product_code",
            (OD_IDENTITY, 3) => "revision",
            (OD_IDENTITY, 4) => "serial",
            (OD_DEVICE_NAME, 0) => "device_name",
            _ => "identity",
        }
    }

    /// Validates the table; `(field, reason)` naming the key under `prefix`.
    pub fn validate(&self, prefix: &str) -> Result<(), (String, String)> {
        if let Some(n) = &self.device_name
            && (n.is_empty() || n.len() > crate::sdo::SDO_MAX)
        {
            return Err((
                format!("{prefix}.identity.device_name"),
                format!("must be 1..={} bytes", crate::sdo::SDO_MAX),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_list_what_is_configured() {
        let id: Identity =
            toml::from_str("vendor_id = 0x000000AB\nserial = 7\ndevice_name = \"x\"").unwrap();
        let c = id.checks();
        assert_eq!(c.len(), 2);
        assert_eq!((c[0].index, c[0].sub, c[0].expected), (0x1018, 1, 0xAB));
        assert_eq!(c[1].key, "serial");
        assert!(toml::from_str::<Identity>("vendor = 1").is_err());
        assert!(toml::from_str::<Identity>("serial = -1").is_err());
        let id = Identity {
            device_name: Some(String::new()),
            ..Default::default()
        };
        assert_eq!(
            id.validate("winch[1]").unwrap_err().0,
            "winch[1].identity.device_name"
        );
    }
}
