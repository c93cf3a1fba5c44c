//! `[view]`: the live view stage (a Foxglove WebSocket server and a web page).

use std::net::SocketAddr;

use serde::{Deserialize, Serialize};

use super::Invalid;

/// The live view's addresses and what it sends.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViewConfig {
    /// Address of the Foxglove WebSocket server (`host:port`; port 0 picks a free one, shown
    /// in the stage's status note). Loopback by default: use the robot's address (or
    /// `0.0.0.0:8765`) to watch from another machine.
    pub bind: String,
    /// Address of the web page (`host:port`, port 0 as for `bind`).
    pub http_bind: String,
    /// Most left images sent per second (each is JPEG-encoded for the clients).
    pub image_hz: f64,
    /// JPEG quality of the left image, 1..=100.
    pub jpeg_quality: u8,
    /// Most disparity, fused-map and point-cloud messages per second.
    pub disparity_hz: f64,
    /// Keep every n-th pixel in each direction for the point cloud (1 = all 76 800).
    pub point_stride: u32,
    /// Farthest point of the point cloud, metres.
    pub max_point_range_m: f64,
}

impl Default for ViewConfig {
    fn default() -> Self {
        Self {
            bind: "127.0.0.1:8765".into(),
            http_bind: "127.0.0.1:8766".into(),
            image_hz: 15.0,
            jpeg_quality: 75,
            disparity_hz: 5.0,
            point_stride: 2,
            max_point_range_m: 8.0,
        }
    }
}

impl ViewConfig {
    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        for (key, addr) in [("bind", &self.bind), ("http_bind", &self.http_bind)] {
            addr.parse::<SocketAddr>().map_err(|e| {
                Invalid::new(
                    key,
                    format!(
                        "= {addr:?} is not an address host:port such as \"127.0.0.1:8765\" ({e})"
                    ),
                )
            })?;
        }
        for (key, hz) in [
            ("image_hz", self.image_hz),
            ("disparity_hz", self.disparity_hz),
        ] {
            if !(hz > 0.0 && hz <= 100.0) {
                return Err(Invalid::new(key, format!("= {hz} must be in (0, 100] Hz")));
            }
        }
        if !(1..=100).contains(&self.jpeg_quality) {
            return Err(Invalid::new(
                "jpeg_quality",
                format!("= {} must be in 1..=100", self.jpeg_quality),
            ));
        }
        if !(1..=16).contains(&self.point_stride) {
            return Err(Invalid::new(
                "point_stride",
                format!("= {} must be in 1..=16", self.point_stride),
            ));
        }
        if !(self.max_point_range_m > 0.0 && self.max_point_range_m <= 100.0) {
            return Err(Invalid::new(
                "max_point_range_m",
                format!("= {} must be in (0, 100] m", self.max_point_range_m),
            ));
        }
        Ok(())
    }

    /// The WebSocket address (checked by [`ViewConfig::validate`]).
    pub fn bind_addr(&self) -> Result<SocketAddr, std::net::AddrParseError> {
        self.bind.parse()
    }

    /// The web page's address (checked by [`ViewConfig::validate`]).
    pub fn http_addr(&self) -> Result<SocketAddr, std::net::AddrParseError> {
        self.http_bind.parse()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_loopback() {
        let v = ViewConfig::default();
        assert!(v.validate().is_ok());
        assert!(
            v.bind_addr()
                .is_ok_and(|a| a.ip().is_loopback() && a.port() == 8765)
        );
        assert!(
            v.http_addr()
                .is_ok_and(|a| a.ip().is_loopback() && a.port() == 8766)
        );
    }

    #[test]
    fn bad_values_name_their_key() {
        let bad = [
            ViewConfig {
                bind: "localhost".into(),
                ..Default::default()
            },
            ViewConfig {
                http_bind: "127.0.0.1:99999".into(),
                ..Default::default()
            },
            ViewConfig {
                image_hz: 0.0,
                ..Default::default()
            },
            ViewConfig {
                jpeg_quality: 0,
                ..Default::default()
            },
            ViewConfig {
                point_stride: 0,
                ..Default::default()
            },
            ViewConfig {
                max_point_range_m: f64::NAN,
                ..Default::default()
            },
        ];
        let keys: Vec<String> = bad
            .iter()
            .map(|v| v.validate().map_or_else(|e| e.key, |()| String::new()))
            .collect();
        assert_eq!(
            keys,
            [
                "bind",
                "http_bind",
                "image_hz",
                "jpeg_quality",
                "point_stride",
                "max_point_range_m"
            ]
        );
    }
}
