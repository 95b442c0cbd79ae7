//! The ROS 2 message types we record and publish live: their `ros2msg` schema texts (with every
//! dependency, in the concatenated form rosbag2 writes) and their CDR serializers. The MCAP
//! writer and the live publishers take the same bytes from here ([`crate::ros2_frame`] puts a
//! frame's messages together), so a live subscriber sees exactly what a recording holds.

use crate::cdr::CdrWriter;

const SEP: &str = "================================================================================\n";

/// `(type, definition)` of every message type used, in `pkg/Name` form.
const DEFS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    (
        "sensor_msgs/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n\
         uint32 step\nuint8[] data\n",
    ),
    (
        "sensor_msgs/PointField",
        "uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\nuint8 UINT32=6\n\
         uint8 FLOAT32=7\nuint8 FLOAT64=8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n",
    ),
    (
        "sensor_msgs/PointCloud2",
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\n\
         bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
    ),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/Quaternion",
        "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
    ),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
    ),
    (
        "sensor_msgs/Imu",
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
         geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
         geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
    ),
    (
        "std_msgs/MultiArrayDimension",
        "string label\nuint32 size\nuint32 stride\n",
    ),
    (
        "std_msgs/MultiArrayLayout",
        "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n",
    ),
    (
        "std_msgs/Float64MultiArray",
        "std_msgs/MultiArrayLayout layout\nfloat64[] data\n",
    ),
    ("std_msgs/String", "string data\n"),
    ("rosgraph_msgs/Clock", "builtin_interfaces/Time clock\n"),
];

/// One ROS 2 message ready to write or publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Message {
    pub topic: String,
    /// The message type, `pkg/Name` (see [`schema_name`] for the `pkg/msg/Name` form).
    pub ty: &'static str,
    /// Sim seconds since the episode's start: the header stamp and the log time.
    pub stamp: f64,
    /// CDR (little-endian XCDR1) with its 4-byte encapsulation header.
    pub data: Vec<u8>,
}

fn def(ty: &str) -> &'static str {
    DEFS.iter().find(|(t, _)| *t == ty).map(|(_, d)| *d).unwrap_or("")
}

/// Message types a definition refers to (fields whose type contains a `/`).
fn deps(ty: &str) -> impl Iterator<Item = &'static str> {
    def(ty).lines().filter_map(|l| {
        let t = l.split_whitespace().next()?;
        let t = t.split('[').next()?;
        t.contains('/')
            .then(|| DEFS.iter().find(|(d, _)| *d == t).map(|(d, _)| *d))?
    })
}

/// The schema text of `ty` (`pkg/Name`) followed by all its dependencies, each once.
pub fn schema(ty: &str) -> String {
    let mut order: Vec<&str> = Vec::new();
    let mut stack: Vec<&str> = deps(ty).collect();
    stack.reverse();
    while let Some(t) = stack.pop() {
        if order.contains(&t) {
            continue;
        }
        order.push(t);
        let mut more: Vec<&str> = deps(t).collect();
        more.reverse();
        stack.extend(more);
    }
    let mut out = def(ty).to_string();
    for t in order {
        out.push_str(SEP);
        out.push_str(&format!("MSG: {t}\n"));
        out.push_str(def(t));
    }
    out
}

/// The MCAP schema name ROS 2 uses: `pkg/msg/Name`.
pub fn schema_name(ty: &str) -> String {
    ty.replacen('/', "/msg/", 1)
}

pub(crate) fn header(w: &mut CdrWriter, t: f64, frame_id: &str) {
    let ns = crate::nanos(t);
    w.i32((ns / 1_000_000_000) as i32);
    w.u32((ns % 1_000_000_000) as u32);
    w.string(frame_id);
}

fn vec3(w: &mut CdrWriter, v: [f64; 3]) {
    v.into_iter().for_each(|x| w.f64(x));
}

/// Quaternion given `[w, x, y, z]`, written in ROS order x, y, z, w.
fn quat(w: &mut CdrWriter, q: [f64; 4]) {
    [q[1], q[2], q[3], q[0]].into_iter().for_each(|x| w.f64(x));
}

pub(crate) fn image(
    t: f64,
    frame: &str,
    width: u32,
    height: u32,
    encoding: &str,
    step: u32,
    data: &[u8],
) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(data.len() + 96);
    header(&mut w, t, frame);
    w.u32(height);
    w.u32(width);
    w.string(encoding);
    w.u8(0);
    w.u32(step);
    w.bytes(data);
    w.finish()
}

/// An unorganised cloud of xyz float32 points.
pub(crate) fn point_cloud(t: f64, frame: &str, points: &[[f32; 3]]) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(points.len() * 12 + 160);
    header(&mut w, t, frame);
    w.u32(1);
    w.u32(points.len() as u32);
    w.len(3);
    for (i, name) in ["x", "y", "z"].into_iter().enumerate() {
        w.string(name);
        w.u32(4 * i as u32);
        w.u8(7); // FLOAT32
        w.u32(1);
    }
    w.bool(false);
    w.u32(12);
    w.u32(12 * points.len() as u32);
    w.len(points.len() * 12);
    let mut data = Vec::with_capacity(points.len() * 12);
    for p in points {
        p.iter().for_each(|c| data.extend_from_slice(&c.to_le_bytes()));
    }
    w.u8_slice_raw(&data);
    w.bool(true);
    w.finish()
}

fn yaw_quat(yaw: f64) -> [f64; 4] {
    [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()]
}

pub(crate) fn odometry(t: f64, pose: [f64; 3], twist: [f64; 2]) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(800);
    header(&mut w, t, "odom");
    w.string("base_link");
    vec3(&mut w, [pose[0], pose[1], 0.0]);
    quat(&mut w, yaw_quat(pose[2]));
    (0..36).for_each(|_| w.f64(0.0));
    vec3(&mut w, [twist[0], 0.0, 0.0]);
    vec3(&mut w, [0.0, 0.0, twist[1]]);
    (0..36).for_each(|_| w.f64(0.0));
    w.finish()
}

/// Standard gravity, m/s²: what an accelerometer at rest on level ground reads along +z.
const GRAVITY: f64 = 9.80665;

/// Diagonal covariances of `/imu` (row-major 3×3). The values come from the simulator's exact
/// odometry, so they are small but not zero (zero would mean "unknown" in ROS):
/// orientation 1e-6 rad², angular velocity 1e-6 (rad/s)²; linear acceleration 1e-2 (m/s²)²,
/// since it is a finite difference of the base speed over one 0.1 s control step.
pub(crate) const IMU_COVARIANCE: [f64; 3] = [1e-6, 1e-6, 1e-2];

/// The base's motion as `sensor_msgs/Imu` in `base_link`: orientation from the odometry yaw
/// (the floor is level, so roll = pitch = 0), angular velocity about z from the measured yaw
/// rate, linear acceleration from the change of the measured base speed over `dt` along x,
/// the centripetal `v·ω` along y, and gravity along z.
pub(crate) fn imu(t: f64, yaw: f64, twist: [f64; 2], previous: Option<(f64, [f64; 2])>) -> Vec<u8> {
    let [v, omega] = twist;
    let ax = match previous {
        Some((t0, [v0, _])) if t > t0 => (v - v0) / (t - t0),
        _ => 0.0,
    };
    let diag = |x: f64| [x, 0.0, 0.0, 0.0, x, 0.0, 0.0, 0.0, x];
    let mut w = CdrWriter::with_capacity(400);
    header(&mut w, t, "base_link");
    quat(&mut w, yaw_quat(yaw));
    diag(IMU_COVARIANCE[0]).into_iter().for_each(|x| w.f64(x));
    vec3(&mut w, [0.0, 0.0, omega]);
    diag(IMU_COVARIANCE[1]).into_iter().for_each(|x| w.f64(x));
    vec3(&mut w, [ax, v * omega, GRAVITY]);
    diag(IMU_COVARIANCE[2]).into_iter().for_each(|x| w.f64(x));
    w.finish()
}

/// `(parent, child, translation, rotation [w, x, y, z])`.
pub(crate) type Tf<'a> = (&'a str, &'a str, [f64; 3], [f64; 4]);

pub(crate) fn tf_message(t: f64, transforms: &[Tf<'_>]) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(128 * transforms.len() + 8);
    w.len(transforms.len());
    for (parent, child, tr, rot) in transforms {
        header(&mut w, t, parent);
        w.string(child);
        vec3(&mut w, *tr);
        quat(&mut w, *rot);
    }
    w.finish()
}

pub(crate) fn base_tf(pose: [f64; 3]) -> ([f64; 3], [f64; 4]) {
    ([pose[0], pose[1], 0.0], yaw_quat(pose[2]))
}

pub(crate) fn twist(v: f64, omega: f64) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(56);
    vec3(&mut w, [v, 0.0, 0.0]);
    vec3(&mut w, [0.0, 0.0, omega]);
    w.finish()
}

/// `rosgraph_msgs/Clock`: sim time, for nodes that run with `use_sim_time`.
pub(crate) fn clock(t: f64) -> Vec<u8> {
    let ns = crate::nanos(t);
    let mut w = CdrWriter::with_capacity(8);
    w.i32((ns / 1_000_000_000) as i32);
    w.u32((ns % 1_000_000_000) as u32);
    w.finish()
}

pub(crate) fn string(s: &str) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(s.len() + 8);
    w.string(s);
    w.finish()
}

pub(crate) fn float64_array(label: &str, data: &[f64]) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(data.len() * 8 + 64);
    w.len(1);
    w.string(label);
    w.u32(data.len() as u32);
    w.u32(data.len() as u32);
    w.u32(0);
    w.len(data.len());
    data.iter().for_each(|x| w.f64(*x));
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schemas_carry_every_dependency_once() {
        let s = schema("nav_msgs/Odometry");
        for dep in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
            "geometry_msgs/TwistWithCovariance",
            "geometry_msgs/Twist",
            "geometry_msgs/Vector3",
        ] {
            assert_eq!(s.matches(&format!("MSG: {dep}\n")).count(), 1, "{dep} in\n{s}");
        }
        assert!(s.starts_with("std_msgs/Header header\n"));
    }

    #[test]
    fn schema_names_use_the_msg_namespace() {
        assert_eq!(schema_name("sensor_msgs/Image"), "sensor_msgs/msg/Image");
    }
}
