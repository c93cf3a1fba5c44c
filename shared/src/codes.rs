//! The codes the payloads carry (`u32` fields of [`messages`](crate::messages)): each enum is
//! declared once, with its wire code and its label, by [`code_enum!`]; `docs/ipc.md` lists them.

/// Declares a `#[repr(u32)]` code enum once, variant by variant with its code and label, and
/// derives from that single list: `ALL` (declaration order), `code`, `from_code`, `label` and
/// `from_label`. With `(unknown = Variant)` after the name, `from_code` reads unknown codes as
/// that variant (the safe choice, e.g. `Stop`) and `try_from_code` returns `None` for them.
macro_rules! code_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident $((unknown = $unknown:ident))? {
            $( $(#[$vmeta:meta])* $variant:ident = $code:literal => $label:literal, )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr(u32)]
        pub enum $name {
            $( $(#[$vmeta])* $variant = $code, )+
        }

        impl $name {
            /// Every value, in declaration order.
            pub const ALL: [Self; [$($code),+].len()] = [$(Self::$variant),+];

            /// The wire code.
            pub const fn code(self) -> u32 {
                self as u32
            }

            /// The value of a wire code; `None` for unknown codes.
            pub const fn try_from_code(code: u32) -> Option<Self> {
                match code {
                    $( $code => Some(Self::$variant), )+
                    _ => None,
                }
            }

            /// The label (status lines, probes, recordings, config files).
            pub const fn label(self) -> &'static str {
                match self {
                    $( Self::$variant => $label, )+
                }
            }

            /// The value of a label; `None` for unknown labels.
            pub fn from_label(label: &str) -> Option<Self> {
                Self::ALL.into_iter().find(|v| v.label() == label)
            }
        }

        code_enum!(@from_code $name $($unknown)?);
    };
    (@from_code $name:ident) => {
        impl $name {
            /// The value of a wire code; `None` for unknown codes.
            pub const fn from_code(code: u32) -> Option<Self> {
                Self::try_from_code(code)
            }
        }
    };
    (@from_code $name:ident $unknown:ident) => {
        impl $name {
            #[doc = concat!("The value of a wire code; unknown codes read as `", stringify!($unknown), "`.")]
            pub const fn from_code(code: u32) -> Self {
                match Self::try_from_code(code) {
                    Some(v) => v,
                    None => Self::$unknown,
                }
            }
        }
    };
}

code_enum! {
    /// Where a frame pair came from.
    pub enum FrameSource {
        /// Rendered by the built-in simulator.
        Simulator = 1 => "sim",
        /// Two V4L2 devices (the Minoru webcam).
        V4l2 = 2 => "v4l2",
        /// A folder of left/right PNG pairs.
        Files = 3 => "files",
        /// An MCAP recording being replayed.
        Replay = 4 => "replay",
    }
}

code_enum! {
    /// Stereo algorithms (the `algorithm` code of a [`DisparityHeader`]).
    #[cfg_attr(feature = "serde", derive(serde::Deserialize, serde::Serialize), serde(rename_all = "kebab-case"))]
    pub enum StereoAlgorithm {
        /// Block matching, sum of absolute differences.
        BmSad = 1 => "bm-sad",
        /// Block matching, sum of squared differences.
        BmSsd = 2 => "bm-ssd",
        /// Block matching, normalised cross-correlation.
        BmNcc = 3 => "bm-ncc",
        /// Block matching, census transform + Hamming distance.
        BmCensus = 4 => "bm-census",
        /// Ogale & Aloimonos shape-and-stereo correspondence.
        Ogale = 5 => "ogale",
        /// Census cost + semi-global matching.
        Sgm = 6 => "sgm",
    }
}

code_enum! {
    /// What the row alignment of a disparity map did (the `row_align` of a [`DisparityHeader`]).
    pub enum RowAlignState {
        /// Off (`row_align.enabled = false`), or not a stereo stage's map.
        Off = 0 => "off",
        /// On, no estimate yet (an untextured view so far).
        Searching = 1 => "searching",
        /// Tracked, below the smallest offset worth applying: the right image was used as is.
        Aligned = 2 => "aligned",
        /// Tracked and applied to the right image before matching.
        Corrected = 3 => "corrected",
    }
}

code_enum! {
    /// Which stereo path a range came from.
    pub enum RangeSource (unknown = None) {
        /// No valid pixels in the window.
        None = 0 => "-",
        /// The 320x240 fast path.
        Lo = 1 => "lo",
        /// The 640x480 long-range path.
        Hi = 2 => "hi",
    }
}

code_enum! {
    /// Motion commands the decision stage can give.
    pub enum MotionCommand (unknown = Stop) {
        /// Neutral pulses: wheels stopped.
        Stop = 0 => "STOP",
        /// Drive straight ahead.
        Forward = 1 => "FWD",
        /// Turn left.
        Left = 2 => "LEFT",
        /// Turn right.
        Right = 3 => "RIGHT",
        /// Back up.
        Reverse = 4 => "REV",
    }
}

code_enum! {
    /// Intersection types of the reference navigation table.
    pub enum IntersectionType (unknown = Unknown) {
        /// Not enough information.
        Unknown = 0 => "unknown",
        /// Walls left, front and right.
        DeadEnd = 1 => "dead-end",
        /// Walls left and front: the way continues right.
        RightTurn = 2 => "right-turn",
        /// Walls front and right: the way continues left.
        LeftTurn = 3 => "left-turn",
        /// Wall in front only: branches left and right.
        TBottom = 4 => "T-bottom",
        /// Walls left and right: a straight hallway.
        StraightHallway = 5 => "hallway",
        /// Wall on the right only: branch left, straight continues.
        TWallRight = 6 => "T-wall-right",
        /// Wall on the left only: branch right, straight continues.
        TWallLeft = 7 => "T-wall-left",
        /// The reference's "B intersection".
        BIntersection = 8 => "B",
        /// No walls: four-way crossing.
        XIntersection = 9 => "X",
    }
}

code_enum! {
    /// Why the actuator sent what it sent.
    pub enum SendReason {
        /// A fresh decision.
        Decision = 1 => "decision",
        /// Neutral: no fresh decision within the watchdog bound.
        WatchdogNeutral = 2 => "watchdog-neutral",
        /// Neutral: the stage is shutting down.
        ShutdownNeutral = 3 => "shutdown-neutral",
        /// Neutral: an internal error.
        ErrorNeutral = 4 => "error-neutral",
        /// Neutral: sent once when the link comes up.
        StartupNeutral = 5 => "startup-neutral",
    }
}

impl SendReason {
    /// True for every neutral (stop) reason.
    pub fn is_neutral(self) -> bool {
        !matches!(self, Self::Decision)
    }
}

code_enum! {
    /// The navigation policy that made a decision (`Decision.policy`; the labels are the
    /// config's `decision.policy` values).
    pub enum NavPolicy {
        /// The reference system: crisp thresholds, the navigation table.
        Reference = 1 => "reference",
        /// Fuzzy walls, hysteresis, dead-reckoned turns and visit memory.
        Fuzzy = 2 => "fuzzy",
        /// Kostavelis et al.'s mean estimation.
        MeanEstimation = 3 => "mean-estimation",
        /// Threshold estimation.
        ThresholdEstimation = 4 => "threshold-estimation",
        /// Frontier exploration on an occupancy grid.
        Explore = 5 => "explore",
    }
}

code_enum! {
    /// Level of a stage's log line ([`LogLine`](crate::messages::LogLine)).
    pub enum LogLevel {
        /// Tracing detail.
        Trace = 1 => "TRACE",
        /// Debugging detail.
        Debug = 2 => "DEBUG",
        /// Normal operation.
        Info = 3 => "INFO",
        /// Something is off but the stage goes on.
        Warn = 4 => "WARN",
        /// Something failed.
        Error = 5 => "ERROR",
    }
}

code_enum! {
    /// Liveness state a stage reports about itself.
    pub enum StageHealth {
        /// Opening devices and services.
        Starting = 1 => "starting",
        /// Working normally.
        Running = 2 => "running",
        /// Running but impaired (for example a device is missing and being retried).
        Degraded = 3 => "degraded",
        /// Shutting down.
        Stopping = 4 => "stopping",
    }
}

code_enum! {
    /// Supervisor-side state of a stage.
    pub enum StageState {
        /// Not running and not going to be started.
        Stopped = 1 => "stopped",
        /// Spawned, no heartbeat yet.
        Starting = 2 => "starting",
        /// Beating.
        Running = 3 => "running",
        /// Waiting out a restart backoff.
        Backoff = 4 => "backoff",
        /// Restarted too often: given up.
        Failed = 5 => "failed",
        /// Disabled in the config.
        Disabled = 6 => "disabled",
        /// Being stopped.
        Stopping = 7 => "stopping",
    }
}

code_enum! {
    /// Requests to the supervisor from `hvs restart` / `hvs stop`.
    pub enum ControlCommand {
        /// Replace one stage in place.
        Restart = 1 => "restart",
        /// Orderly stop of the whole pipeline.
        Stop = 2 => "stop",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    macro_rules! check_codes {
        ($($name:ident),+) => {$(
            let mut labels = Vec::new();
            for v in $name::ALL {
                assert_eq!($name::try_from_code(v.code()), Some(v), stringify!($name));
                assert_eq!($name::from_label(v.label()), Some(v), stringify!($name));
                labels.push(v.label());
            }
            let count = labels.len();
            labels.sort_unstable();
            labels.dedup();
            assert_eq!(labels.len(), count, "{}: labels not unique", stringify!($name));
            assert_eq!($name::try_from_code(u32::MAX), None, stringify!($name));
            assert_eq!($name::from_label("no such label"), None, stringify!($name));
        )+};
    }

    #[test]
    fn every_code_and_label_round_trips() {
        check_codes!(
            FrameSource,
            StereoAlgorithm,
            RowAlignState,
            RangeSource,
            MotionCommand,
            IntersectionType,
            SendReason,
            StageHealth,
            StageState,
            ControlCommand
        );
    }

    /// The `codes` cell of an enum's row in docs/ipc.md: `0 `STOP`, 1 `FWD`, ...`.
    macro_rules! doc_cells {
        ($($name:ident),+) => {
            [$((
                stringify!($name),
                $name::ALL
                    .iter()
                    .map(|v| format!("{} `{}`", v.code(), v.label()))
                    .collect::<Vec<_>>()
                    .join(", "),
            )),+]
        };
    }

    #[test]
    fn the_codes_section_of_docs_ipc_md_lists_every_code() {
        let doc = include_str!("../../docs/ipc.md");
        let rows = doc_cells!(
            FrameSource,
            StereoAlgorithm,
            RowAlignState,
            RangeSource,
            MotionCommand,
            IntersectionType,
            SendReason,
            StageHealth,
            StageState,
            ControlCommand
        );
        for (name, codes) in rows {
            let row = doc
                .lines()
                .find(|l| l.starts_with(&format!("| `{name}` |")))
                .unwrap_or_else(|| panic!("docs/ipc.md has no row for {name}"));
            assert!(
                row.ends_with(&format!("| {codes} |")),
                "docs/ipc.md, {name}: {row}\nthe code says: {codes}"
            );
        }
    }

    #[test]
    fn unknown_codes_read_as_the_safe_value_where_one_is_declared() {
        assert_eq!(MotionCommand::from_code(99), MotionCommand::Stop);
        assert_eq!(IntersectionType::from_code(99), IntersectionType::Unknown);
        assert_eq!(RangeSource::from_code(99), RangeSource::None);
        assert_eq!(SendReason::from_code(99), None);
        assert_eq!(StereoAlgorithm::from_code(6), Some(StereoAlgorithm::Sgm));
    }
}
