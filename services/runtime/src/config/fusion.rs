//! `[fusion]`: edges, disparity and the ranges per window.

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Range statistic over a window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RangeStatistic {
    /// Mean of the edge pixels' ranges (the reference).
    Mean,
    /// Median.
    Median,
    /// Mean of the middle 60 % (20 % trimmed off each end).
    TrimmedMean,
    /// The `near_percentile` percentile: the nearest obstacle, robust to a few outliers.
    Percentile,
}

/// Edge detector of the fusion stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EdgeDetector {
    /// Canny (the reference): smoothing, Sobel, non-maximum suppression, hysteresis.
    Canny,
    /// Sobel magnitude above `canny_high` (the reference compared it and found it worse).
    Sobel,
}

/// How the obstacle scan judges a bin's points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScanFilter {
    /// A low percentile of each bin's points, whatever their spread (what the `fuzzy`
    /// navigator was tuned on).
    #[default]
    None,
    /// Per image column, only depths the column's points agree on; a bin whose columns all
    /// scatter (a wall nearer than the matcher's shortest range) reads as scattered, not
    /// as open space. For `policy = "explore"` (docs/navigation.md has the measurements).
    Agreement,
}

/// Edges, fused map and ranges.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FusionConfig {
    /// Edge detector.
    pub edges: EdgeDetector,
    /// Canny low threshold on the gradient magnitude (|gx| + |gy| of a 3x3 Sobel).
    pub canny_low: u32,
    /// Canny high threshold.
    pub canny_high: u32,
    /// Number of vertical windows: 3 or 5.
    pub windows: u32,
    /// Statistic reported as `range_m`.
    pub statistic: RangeStatistic,
    /// A 640x480 result older than this (relative to the fast-path frame) is not fused.
    pub hi_max_age_ms: u64,
    /// Percentile reported as `near_m` (and used by the `percentile` statistic), 0..=50.
    pub near_percentile: f64,
    /// Points lower than this above the floor are floor, not obstacles (0 disables).
    pub min_height_m: f64,
    /// Points higher than this above the floor are ignored (ceiling; 0 disables).
    pub max_height_m: f64,
    /// A fast-path window with fewer valid pixels than this takes a fresh 640x480 value
    /// instead (the fast path cannot see beyond its disparity range).
    pub min_valid_px: u32,
    /// Edge pixels whose disparity confidence (0..1, the stereo stage's plane) is below this
    /// are left out of the ranges; the others weigh by their confidence in the mean and in
    /// the window's confidence.
    pub min_confidence: f32,
    /// How the obstacle scan judges a bin's points.
    pub scan_filter: ScanFilter,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            edges: EdgeDetector::Canny,
            canny_low: 60,
            canny_high: 150,
            windows: 3,
            statistic: RangeStatistic::Mean,
            hi_max_age_ms: 300,
            near_percentile: 10.0,
            min_height_m: 0.05,
            max_height_m: 1.5,
            min_valid_px: 30,
            min_confidence: 0.05,
            scan_filter: ScanFilter::None,
        }
    }
}

impl FusionConfig {
    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        let f = self;
        if f.windows != 3 && f.windows != 5 {
            return Err(Invalid::new(
                "windows",
                format!("= {} must be 3 or 5", f.windows),
            ));
        }
        if f.canny_low >= f.canny_high {
            return Err(Invalid::new(
                "canny_low",
                format!(
                    "= {} must be below canny_high = {}",
                    f.canny_low, f.canny_high
                ),
            ));
        }
        if !(0.0..=1.0).contains(&f.min_confidence) {
            return Err(Invalid::new(
                "min_confidence",
                format!("= {} must be in 0..=1", f.min_confidence),
            ));
        }
        if !(0.0..=50.0).contains(&f.near_percentile) {
            return Err(Invalid::new(
                "near_percentile",
                format!("= {} must be in 0..=50", f.near_percentile),
            ));
        }
        if f.min_height_m < 0.0
            || f.max_height_m < 0.0
            || (f.max_height_m > 0.0 && f.max_height_m <= f.min_height_m)
        {
            return Err(Invalid::new(
                "max_height_m",
                format!(
                    "min_height_m = {} and max_height_m = {} must be >= 0 with max above min (0 disables)",
                    f.min_height_m, f.max_height_m
                ),
            ));
        }
        Ok(())
    }
}
