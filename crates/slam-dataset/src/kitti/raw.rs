//! KITTI raw drives: OXTS packets (GPS/IMU) turned into poses, timestamps, and the per-date
//! calibration (`calib_cam_to_cam.txt`, `calib_velo_to_cam.txt`, `calib_imu_to_velo.txt`).

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Matrix3x4, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::{kitti::calib::Calib, parse_exact, read_text, DatasetError};

/// Earth radius used by the KITTI devkit for the Mercator projection, metres.
const EARTH_RADIUS: f64 = 6_378_137.0;

/// One OXTS packet (the first 6 of its 30 values are used for poses).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OxtsPacket {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Altitude, metres.
    pub alt: f64,
    /// Roll, radians (about the IMU x axis, forward).
    pub roll: f64,
    /// Pitch, radians (about y, left).
    pub pitch: f64,
    /// Yaw, radians (about z, up; 0 = east).
    pub yaw: f64,
    /// All 30 values, in the order of `oxts/dataformat.txt`.
    pub values: [f64; 30],
}

impl OxtsPacket {
    /// The IMU's orientation in the local east-north-up frame: `Rz(yaw)·Ry(pitch)·Rx(roll)`.
    pub fn orientation(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), self.pitch)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.roll)
    }
}

/// Read one packet file (one line of 30 numbers).
pub fn read_oxts_packet(path: impl AsRef<Path>) -> Result<OxtsPacket, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path, &slam_core::files::SMALL)?;
    parse_oxts_packet(path, &text)
}

/// Parse the contents of such a file; `path` only names it in error messages.
pub fn parse_oxts_packet(path: &Path, text: &str) -> Result<OxtsPacket, DatasetError> {
    let Some((i, line)) = text.lines().enumerate().find(|(_, l)| !l.trim().is_empty()) else {
        return Err(DatasetError::Invalid { path: path.to_path_buf(), message: "empty OXTS packet".into() });
    };
    let fields: Vec<&str> = line.split_whitespace().collect();
    let v = parse_exact(path, i + 1, &fields, 30)?;
    let mut values = [0.0; 30];
    values.copy_from_slice(&v);
    // geographic coordinates: the Mercator projection of the poses is defined for |lat| < 90
    if !(v[0].abs() < 90.0 && v[1].abs() <= 180.0) {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line: i + 1,
            message: format!(
                "latitude {} / longitude {} are not geographic coordinates (|lat| < 90, |lon| <= 180)",
                short(v[0]),
                short(v[1])
            ),
        });
    }
    Ok(OxtsPacket { lat: v[0], lon: v[1], alt: v[2], roll: v[3], pitch: v[4], yaw: v[5], values })
}

/// A number for a message: as written up to a million, in scientific notation beyond.
fn short(v: f64) -> String {
    if v.abs() < 1e6 {
        format!("{v}")
    } else {
        format!("{v:.3e}")
    }
}

/// IMU poses in a local metric frame, as the KITTI devkit's `convertOxtsToPose`: a Mercator projection
/// with the scale `cos(lat₀)` of the first packet, `x = s·R·lon·π/180`, `y = s·R·ln(tan(π(90 + lat)/360))`,
/// `z = alt`, orientation `Rz(yaw)·Ry(pitch)·Rx(roll)`; every pose is expressed relative to the first, so
/// the first is the identity. The IMU frame is x forward, y left, z up.
pub fn oxts_poses(packets: &[OxtsPacket]) -> Vec<Isometry3<f64>> {
    let Some(first) = packets.first() else { return Vec::new() };
    let scale = (first.lat.to_radians()).cos();
    let absolute = |p: &OxtsPacket| {
        let mx = scale * EARTH_RADIUS * p.lon.to_radians();
        let my = scale * EARTH_RADIUS * ((90.0 + p.lat).to_radians() / 2.0).tan().ln();
        Isometry3::from_parts(Translation3::new(mx, my, p.alt), p.orientation())
    };
    let origin_inv = absolute(first).inverse();
    packets.iter().map(|p| origin_inv * absolute(p)).collect()
}

/// Fastest a vehicle carrying the rig moves, m/s: 100 m/s (360 km/h) is beyond any road vehicle;
/// KITTI's drives stay under 30 m/s.
pub const MAX_VEHICLE_SPEED_MPS: f64 = 100.0;

/// Fastest a vehicle turns, rad/s: a full turn a second, beyond a car spinning out (a car's yaw rate
/// stays under 1 rad/s).
pub const MAX_VEHICLE_TURN_RADPS: f64 = std::f64::consts::TAU;

/// GPS fixes are trusted to this many times their `pos_accuracy` when two packets' positions are
/// compared.
const POSITION_ACCURACY_SIGMAS: f64 = 5.0;

/// Most `pos_accuracy` a fix counts with, metres. A stand-alone civilian GPS fix is within about 9 m
/// horizontally 95 % of the time (the GPS Standard Positioning Service performance standard, 2008), so
/// a receiver claiming worse than 20 m has no real fix; without this cap one packet's claim (10^6 m)
/// would open the jump check to any distance (a 1.1 km jump passed). With it the reach is at most
/// 5 × 2 × 20 = 200 m beyond the vehicle's own travel.
pub const MAX_FIX_ACCURACY_M: f64 = 20.0;

/// Packets whose step from the packet before no vehicle makes: their positions (Mercator, as
/// [`oxts_poses`]) further apart than [`MAX_VEHICLE_SPEED_MPS`] over the time between their frames
/// plus [`POSITION_ACCURACY_SIGMAS`] times both fixes' `pos_accuracy` (each at most
/// [`MAX_FIX_ACCURACY_M`]), or their orientations turned
/// faster than [`MAX_VEHICLE_TURN_RADPS`]. `names` name the packets in the error (their files).
pub fn check_oxts_steps(packets: &[OxtsPacket], times: &[f64], names: &[&Path]) -> Result<(), DatasetError> {
    let poses = oxts_poses(packets);
    for k in 1..packets.len().min(times.len()).min(names.len()) {
        let dt = times[k] - times[k - 1];
        let (a, b) = (&poses[k - 1], &poses[k]);
        let step = (b.translation.vector - a.translation.vector).norm();
        // NaN accuracy counts as none: `min` keeps the cap
        let fix = |p: &OxtsPacket| p.values[OXTS_POS_ACCURACY].abs().min(MAX_FIX_ACCURACY_M);
        let accuracy = fix(&packets[k - 1]) + fix(&packets[k]);
        let reach = MAX_VEHICLE_SPEED_MPS * dt + POSITION_ACCURACY_SIGMAS * accuracy;
        let turn = a.rotation.angle_to(&b.rotation);
        // a non-finite step or turn is no vehicle's either
        let impossible = if step.is_nan() || step > reach {
            Some(format!(
                "the IMU moved {} m from the packet before ({}) in {dt:.3} s: more than a vehicle travels (at most {MAX_VEHICLE_SPEED_MPS} m/s) plus {POSITION_ACCURACY_SIGMAS} × the two fixes' position accuracy ({accuracy:.2} m)",
                if step < 1e6 { format!("{step:.1}") } else { format!("{step:.3e}") },
                names[k - 1].display()
            ))
        } else if turn.is_nan() || turn > MAX_VEHICLE_TURN_RADPS * dt {
            Some(format!(
                "the IMU turned {:.1}° from the packet before ({}) in {dt:.3} s: faster than a vehicle turns (at most {:.0}°/s)",
                turn.to_degrees(),
                names[k - 1].display(),
                MAX_VEHICLE_TURN_RADPS.to_degrees()
            ))
        } else {
            None
        };
        if let Some(message) = impossible {
            return Err(DatasetError::Invalid { path: names[k].to_path_buf(), message });
        }
    }
    Ok(())
}

/// Index of `pos_accuracy` (metres, the receiver's position accuracy) among an OXTS packet's 30 values.
pub const OXTS_POS_ACCURACY: usize = 23;

/// Indices of `vn`, `ve` and `vu` (metres per second: north, east, up) among an OXTS packet's 30 values.
pub const OXTS_VELOCITY: [usize; 3] = [6, 7, 10];

/// Two measures of the path of the IMU over `packets` (one per frame, at `times` seconds): the sum of
/// the steps between their positions ([`oxts_poses`]: GPS, Mercator) and the packets' speed integrated
/// over time (trapezoid). The INS's velocities are far more precise than its positions (the drives'
/// `vel_accuracy` is a few cm/s, `pos_accuracy` a few decimetres), so where the two disagree the
/// positions' scale is off by about that much over this stretch. `None` for fewer than two packets or
/// times that do not match them.
pub fn oxts_path_lengths(packets: &[OxtsPacket], times: &[f64]) -> Option<OxtsPath> {
    if packets.len() < 2 || times.len() != packets.len() {
        return None;
    }
    let poses = oxts_poses(packets);
    let positions_m = poses.windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum();
    let speed = |p: &OxtsPacket| OXTS_VELOCITY.iter().map(|&i| p.values[i] * p.values[i]).sum::<f64>().sqrt();
    let velocities_m = packets
        .windows(2)
        .zip(times.windows(2))
        .map(|(p, t)| 0.5 * (speed(&p[0]) + speed(&p[1])) * (t[1] - t[0]))
        .sum();
    Some(OxtsPath { positions_m, velocities_m })
}

/// The IMU's path over a drive's frames, measured two ways ([`oxts_path_lengths`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OxtsPath {
    /// Sum of the steps between the GPS positions, metres.
    pub positions_m: f64,
    /// The INS's speed integrated over the frame times, metres.
    pub velocities_m: f64,
}

impl OxtsPath {
    /// How much longer the positions' path is than the velocities', per cent (negative: shorter).
    pub fn position_excess_pct(&self) -> f64 {
        100.0 * (self.positions_m / self.velocities_m - 1.0)
    }
}

/// IMU poses from the INS alone, relative to the first packet (as [`oxts_poses`], without the GPS
/// positions): each packet's orientation, and positions from its velocity over ground (`v_e, v_n, v_u`,
/// east / north / up: the axes of the Mercator frame) integrated over `times` (trapezoid). Over a
/// drive's stretch this dead reckoning is steadier than the positions, whose GPS fixes jump by
/// decimetres (`pos_accuracy`) where the velocities are good to a few cm/s (`vel_accuracy`); over
/// kilometres it drifts. `None` for fewer than two packets or times that do not match them.
pub fn oxts_dead_reckoning(packets: &[OxtsPacket], times: &[f64]) -> Option<Vec<Isometry3<f64>>> {
    if packets.len() < 2 || times.len() != packets.len() {
        return None;
    }
    let [n, e, u] = OXTS_VELOCITY;
    let velocity = |p: &OxtsPacket| Vector3::new(p.values[e], p.values[n], p.values[u]);
    let mut at = Vector3::zeros();
    let mut absolute = vec![Isometry3::from_parts(Translation3::from(at), packets[0].orientation())];
    for (p, t) in packets.windows(2).zip(times.windows(2)) {
        at += 0.5 * (velocity(&p[0]) + velocity(&p[1])) * (t[1] - t[0]);
        absolute.push(Isometry3::from_parts(Translation3::from(at), p[1].orientation()));
    }
    let origin_inv = absolute[0].inverse();
    Some(absolute.iter().map(|a| origin_inv * a).collect())
}

/// Poses of the rectified camera 0 (world = the first packet's camera, camera-to-world) from OXTS
/// packets, as the KITTI devkit chains them: IMU poses of [`oxts_poses`] (Mercator with the first
/// packet's latitude as scale), then IMU → Velodyne (`calib_imu_to_velo`) → camera 0
/// (`calib_velo_to_cam`) → rectified camera 0 (`R_rect_00`):
/// `T_w←cam(i) = C · T_imu₀←imu(i) · C⁻¹` with `C = T_rect←velo · T_velo←imu`.
pub fn camera_poses_from_oxts(packets: &[OxtsPacket], calib: &RawCalib) -> Vec<Isometry3<f64>> {
    camera_poses_from_imu(oxts_poses(packets), calib)
}

/// Camera-0 poses of IMU poses (relative to the first), chained as [`camera_poses_from_oxts`] does.
pub fn camera_poses_from_imu(imu: Vec<Isometry3<f64>>, calib: &RawCalib) -> Vec<Isometry3<f64>> {
    let cam_from_imu = calib.rect_from_velo() * calib.velo_from_imu;
    let imu_from_cam = cam_from_imu.inverse();
    imu.into_iter().map(|p| cam_from_imu * p * imu_from_cam).collect()
}

/// Read a KITTI `timestamps.txt` (`YYYY-MM-DD HH:MM:SS.fffffffff` per line) as seconds since the first
/// line, dates included (a clock earlier on the same date is an error, not a midnight crossing).
pub fn read_timestamps(path: impl AsRef<Path>) -> Result<Vec<f64>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path, &slam_core::files::TABLE)?;
    parse_timestamps(path, &text)
}

/// Parse the contents of such a file; `path` only names it in error messages.
pub fn parse_timestamps(path: &Path, text: &str) -> Result<Vec<f64>, DatasetError> {
    let mut out = Vec::new();
    let mut first_day: Option<i64> = None;
    let mut last = f64::NEG_INFINITY;
    for (n, line) in crate::frame_lines(path, text)? {
        let err = |m: &str| DatasetError::Parse { path: path.to_path_buf(), line: n, message: m.into() };
        let mut fields = line.split_whitespace();
        let date = fields.next().unwrap_or_default();
        let time = fields.next().ok_or_else(|| err("expected 'date time'"))?;
        let day = civil_day(date).ok_or_else(|| err(&format!("{date} is not a date (YYYY-MM-DD)")))?;
        let parts: Vec<&str> = time.split(':').collect();
        if parts.len() != 3 {
            return Err(err("time must be HH:MM:SS.fraction"));
        }
        let h: f64 = parts[0].parse().map_err(|_| err("bad hour"))?;
        let m: f64 = parts[1].parse().map_err(|_| err("bad minute"))?;
        let s: f64 = parts[2].parse().map_err(|_| err("bad second"))?;
        if !(h.is_finite() && m.is_finite() && s.is_finite()) {
            return Err(err("non-finite time"));
        }
        // a clock time: hours 0–23, minutes 0–59, seconds below 61 (a leap second)
        if !((0.0..24.0).contains(&h) && (0.0..60.0).contains(&m) && (0.0..61.0).contains(&s)) {
            return Err(err(&format!("{time} is not a time of day (HH 0-23, MM 0-59, SS below 61)")));
        }
        // seconds from the first line's day: the date says when the clock passed midnight
        let t = (day - *first_day.get_or_insert(day)) as f64 * 86_400.0 + h * 3600.0 + m * 60.0 + s;
        if t <= last {
            return Err(err(&format!(
                "{date} {time} is not after the line before ({:.3} s earlier or the same): frames are in time order",
                last - t
            )));
        }
        if let Some(m) = crate::kitti::frames::next_time_error(last, t).filter(|_| last.is_finite()) {
            return Err(err(&m));
        }
        last = t;
        out.push(t);
    }
    if let Some(&t0) = out.first() {
        for t in &mut out {
            *t -= t0;
        }
    }
    Ok(out)
}

/// Days from 1970-01-01 of a `YYYY-MM-DD` date of the Gregorian calendar (`None` if it is none).
fn civil_day(date: &str) -> Option<i64> {
    let mut it = date.split('-');
    let (y, m, d): (i64, i64, i64) = (it.next()?.parse().ok()?, it.next()?.parse().ok()?, it.next()?.parse().ok()?);
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let month_days = [31, if leap { 29 } else { 28 }, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
    if it.next().is_some()
        || !(1..=9999).contains(&y)
        || !(1..=12).contains(&m)
        || d < 1
        || d > month_days[(m - 1) as usize]
    {
        return None;
    }
    // whole years since 1970 (leap days counted), then the months of this year
    let leaps_before = |y: i64| (y - 1) / 4 - (y - 1) / 100 + (y - 1) / 400;
    let days_to_year = (y - 1970) * 365 + leaps_before(y) - leaps_before(1970);
    let days_to_month: i64 = month_days[..(m - 1) as usize].iter().sum();
    Some(days_to_year + days_to_month + d - 1)
}

/// The calibration of a raw-data date folder.
#[derive(Debug, Clone, PartialEq)]
pub struct RawCalib {
    /// Rectified projection matrices `P_rect_00..03` (rectified cam 0 frame to image).
    pub p_rect: [Matrix3x4<f64>; 4],
    /// Rectifying rotation of camera 0, `R_rect_00`.
    pub r_rect_00: Matrix3<f64>,
    /// Velodyne to (unrectified) camera 0.
    pub cam0_from_velo: Isometry3<f64>,
    /// IMU to Velodyne.
    pub velo_from_imu: Isometry3<f64>,
    /// Rectified image size `S_rect_02` (width, height).
    pub image_size: [f64; 2],
}

impl RawCalib {
    /// Read `calib_cam_to_cam.txt`, `calib_velo_to_cam.txt` and `calib_imu_to_velo.txt` from a date
    /// folder (e.g. `2011_09_26/`).
    pub fn read(date_dir: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let d = date_dir.as_ref();
        let c2c = Calib::read(d.join("calib_cam_to_cam.txt"))?;
        let v2c = Calib::read(d.join("calib_velo_to_cam.txt"))?;
        let i2v = Calib::read(d.join("calib_imu_to_velo.txt"))?;
        let p = |k: &str| c2c.matrix3x4(k);
        let size = c2c.numbers("S_rect_02", Some(2))?;
        Ok(Self {
            p_rect: [p("P_rect_00")?, p("P_rect_01")?, p("P_rect_02")?, p("P_rect_03")?],
            r_rect_00: c2c.rotation("R_rect_00")?,
            cam0_from_velo: v2c.rigid("R", "T")?,
            velo_from_imu: i2v.rigid("R", "T")?,
            image_size: [size[0], size[1]],
        })
    }

    /// The rectified camera-0 frame from the Velodyne frame: `R_rect_00 · T_cam0←velo`.
    pub fn rect_from_velo(&self) -> Isometry3<f64> {
        let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&self.r_rect_00));
        Isometry3::from_parts(Translation3::identity(), r) * self.cam0_from_velo
    }
}
