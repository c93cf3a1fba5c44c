//! rmw_zenoh's naming (ros2/rmw_zenoh docs/design.md, and liveliness_utils.cpp and
//! attachment_helpers.cpp for the details the design leaves out): data key expressions,
//! liveliness tokens that put the node and its publishers in the ROS graph, and the
//! attachment every sample carries.

/// A ROS 2 message type the bridge publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RosType {
    /// sensor_msgs/msg/Image.
    Image,
    /// sensor_msgs/msg/CameraInfo.
    CameraInfo,
    /// stereo_msgs/msg/DisparityImage.
    DisparityImage,
    /// geometry_msgs/msg/Twist.
    Twist,
}

impl RosType {
    /// The DDS-mangled type name rmw_zenoh puts in keys (`sensor_msgs::msg::dds_::Image_`).
    pub const fn dds_name(self) -> &'static str {
        match self {
            RosType::Image => "sensor_msgs::msg::dds_::Image_",
            RosType::CameraInfo => "sensor_msgs::msg::dds_::CameraInfo_",
            RosType::DisparityImage => "stereo_msgs::msg::dds_::DisparityImage_",
            RosType::Twist => "geometry_msgs::msg::dds_::Twist_",
        }
    }

    /// The ROS name (`sensor_msgs/msg/Image`).
    pub const fn ros_name(self) -> &'static str {
        match self {
            RosType::Image => "sensor_msgs/msg/Image",
            RosType::CameraInfo => "sensor_msgs/msg/CameraInfo",
            RosType::DisparityImage => "stereo_msgs/msg/DisparityImage",
            RosType::Twist => "geometry_msgs/msg/Twist",
        }
    }

    /// The type's RIHS01 hash in ROS 2 Jazzy (the same from
    /// `/opt/ros/jazzy/share/<pkg>/msg/<Type>.json` and from rosbags' `hash_rihs01`, which the
    /// end-to-end test recomputes).
    pub const fn type_hash(self) -> &'static str {
        match self {
            RosType::Image => {
                "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"
            }
            RosType::CameraInfo => {
                "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275"
            }
            RosType::DisparityImage => {
                "RIHS01_1ec1ff6b5bace919e4544a37f2d96ead9f81783701b7b7a4d97a09325ecf2711"
            }
            RosType::Twist => {
                "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
            }
        }
    }
}

/// rmw_zenoh's QoS field for a reliable, volatile, keep-last-10 publisher: every value equal
/// to rmw_zenoh's default is left empty (`R:D:H,depth:deadline:lifespan:liveliness`).
pub const QOS_RELIABLE_DEPTH_10: &str = "::,10:,:,:,,";

/// `/hvs/left/image_raw` -> `%hvs%left%image_raw` (an empty name or `/` -> `%`).
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// The full topic name of `relative` in `namespace` (`/hvs` + `left/image_raw`).
pub fn full_topic(namespace: &str, relative: &str) -> String {
    if namespace == "/" {
        format!("/{relative}")
    } else {
        format!("{namespace}/{relative}")
    }
}

/// The data key expression: `<domain>/<topic without its leading slash>/<type>/<hash>`.
pub fn data_key(domain_id: u32, topic: &str, ty: RosType) -> String {
    format!(
        "{domain_id}/{}/{}/{}",
        topic.trim_matches('/'),
        ty.dds_name(),
        ty.type_hash()
    )
}

/// The ROS 2 node the bridge appears as.
#[derive(Debug, Clone, Copy)]
pub struct RosNode<'a> {
    /// `ROS_DOMAIN_ID`.
    pub domain_id: u32,
    /// The zenoh session id (32 hex digits).
    pub zid: &'a str,
    /// The node's id within the session.
    pub node_id: u32,
    /// The node's namespace (`/hvs`).
    pub namespace: &'a str,
    /// The node's name.
    pub node: &'a str,
}

impl RosNode<'_> {
    /// The node's liveliness token.
    pub fn token(&self) -> String {
        format!(
            "@ros2_lv/{}/{}/{}/{}/NN/%/{}/{}",
            self.domain_id,
            self.zid,
            self.node_id,
            self.node_id,
            mangle(self.namespace),
            self.node
        )
    }

    /// The liveliness token of the node's publisher `entity_id` on `topic` (a full name).
    pub fn publisher_token(&self, entity_id: u32, topic: &str, ty: RosType) -> String {
        format!(
            "@ros2_lv/{}/{}/{}/{entity_id}/MP/%/{}/{}/{}/{}/{}/{QOS_RELIABLE_DEPTH_10}",
            self.domain_id,
            self.zid,
            self.node_id,
            mangle(self.namespace),
            self.node,
            mangle(topic),
            ty.dds_name(),
            ty.type_hash()
        )
    }
}

/// The attachment of every rmw_zenoh sample (33 bytes, zenoh-ext serialisation): sequence
/// number (i64), source time (i64 ns since the Unix epoch), then the 16-byte publisher GID
/// with its length (16) first.
pub fn attachment(seq: i64, source_wall_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut a = [0u8; 33];
    a[0..8].copy_from_slice(&seq.to_le_bytes());
    a[8..16].copy_from_slice(&source_wall_ns.to_le_bytes());
    a[16] = 16;
    a[17..33].copy_from_slice(gid);
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_and_tokens_follow_the_design_document() {
        assert_eq!(
            data_key(0, "/hvs/left/image_raw", RosType::Image),
            "0/hvs/left/image_raw/sensor_msgs::msg::dds_::Image_/RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"
        );
        let node = RosNode {
            domain_id: 0,
            zid: "abc",
            node_id: 0,
            namespace: "/hvs",
            node: "hvs_bridge",
        };
        assert_eq!(node.token(), "@ros2_lv/0/abc/0/0/NN/%/%hvs/hvs_bridge");
        let root = RosNode {
            domain_id: 3,
            namespace: "/",
            node: "n",
            ..node
        };
        let t = root.publisher_token(2, "/cmd", RosType::Twist);
        assert!(t.starts_with(
            "@ros2_lv/3/abc/0/2/MP/%/%/n/%cmd/geometry_msgs::msg::dds_::Twist_/RIHS01_"
        ));
        assert!(t.ends_with("/::,10:,:,:,,"));
        assert_eq!(full_topic("/", "x"), "/x");
        assert_eq!(full_topic("/hvs", "left/image_raw"), "/hvs/left/image_raw");
        let a = attachment(1, 2, &[9; 16]);
        assert_eq!(a[16], 16);
        assert_eq!(&a[0..8], &1i64.to_le_bytes());
        for ty in [
            RosType::Image,
            RosType::CameraInfo,
            RosType::DisparityImage,
            RosType::Twist,
        ] {
            assert_eq!(ty.type_hash().len(), 71);
        }
    }
}
