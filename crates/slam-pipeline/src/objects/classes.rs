//! What the mapper knows of each class: the size prior of its fits ([`class_prior`]) and the extents no
//! real object of the class has ([`physical_limits`]). (The classes a detector confuses on one object
//! are grouped by `slam_core::ClassId::group`.)

use nalgebra::Vector3;
use slam_core::ClassId;
use slam_optim::object::ObjectPrior;

/// Class priors of semi-axes (own x = length, y = height, z = width), from KITTI's average label
/// dimensions (cars 3.9 × 1.5 × 1.6 m), COCO class ids.
pub fn class_prior(class: ClassId) -> ObjectPrior {
    let (a, s) = match class.0 {
        0 => ((0.45, 0.87, 0.35), (0.15, 0.15, 0.1)),  // person
        1 | 3 => ((0.9, 0.87, 0.3), (0.2, 0.15, 0.1)), // bicycle, motorcycle
        5..=7 => ((3.5, 1.5, 1.25), (1.5, 0.5, 0.3)),  // bus, train, truck
        _ => ((1.95, 0.77, 0.82), (0.3, 0.1, 0.1)),    // car and others
    };
    ObjectPrior { axes: Vector3::new(a.0, a.1, a.2), sigma: Vector3::new(s.0, s.1, s.2) }
}

/// Physical extents (full lengths in metres, not semi-axes) a real object of a class can have: the
/// smallest extent at least `min`, the largest at most `max_length`, the middle one (height or width,
/// whichever is larger) at most `max_middle`. Any ellipsoid outside them is a wrong fit, whatever its
/// stereo points say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalLimits {
    /// Smallest extent at least this.
    pub min: f64,
    /// Largest extent at most this.
    pub max_length: f64,
    /// Middle extent at most this.
    pub max_middle: f64,
}

/// The limits of a class's real objects (see [`PhysicalLimits`]); sources:
/// - buses and trucks: EU Directive 96/53/EC (as amended) and US 23 CFR 658 cap the width at
///   2.55-2.60 m and the length at 18.75 m (road train, articulated bus); heights reach 4.0-4.3 m
///   (most EU states; 13 ft 6 in - 14 ft in the US). Length limit 20 m and middle extent (height) 4.5 m
///   leave room for fit error. The narrowest vehicles a detector calls a truck are pickups (~1.8 m
///   wide, ~1.7 m tall): no extent under half of that, 0.9 m.
/// - cars (the detector's "car" also covers vans and SUVs): the longest production vans and pickups are
///   about 7.4 m (long-wheelbase panel vans), the tallest about 3 m (high-roof vans); the narrowest
///   and lowest road cars about 1.2 m wide (quadricycles) and 1.0 m tall (sports cars). Limits 8 m,
///   3.5 m and half the lowest car, 0.5 m.
/// - people: no one is taller than 2.5 m, and a walking person with arms and bags spans less than
///   2 m across; at least 0.1 m (the thinnest a fitted ellipsoid may be and still be a body).
/// - bicycles and motorcycles with riders: at most 3.2 m long (touring motorcycles 2.6 m, tandems
///   2.5 m, plus fit error), 2.2 m tall; at least 0.1 m (a bicycle seen end-on is thin).
///
/// A fit misses an object's true extents by its fitting error (semi-axes 0.75 m off on average for the
/// parked van of drive 0005, 0.33 m image-free, where real cars are fitted as thin as 0.65 m); the
/// limits lie beyond what real objects reach (a minimum at half the smallest real extent), so that a
/// real object fitted that badly is still kept (the class prior and the stereo gate deal with it).
pub fn physical_limits(class: ClassId) -> PhysicalLimits {
    let (min, max_length, max_middle) = match class.0 {
        0 => (0.1, 2.5, 2.0),      // person
        1 | 3 => (0.1, 3.2, 2.2),  // bicycle, motorcycle
        5..=7 => (0.9, 20.0, 4.5), // bus, train, truck
        _ => (0.5, 8.0, 3.5),      // car and others
    };
    PhysicalLimits { min, max_length, max_middle }
}

/// Whether an ellipsoid with `semi_axes` could be a real object of `class` ([`physical_limits`]);
/// `Err` says which extent is impossible.
// `!(x <= limit)` on purpose: a NaN extent fails every test
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn physically_plausible(class: ClassId, semi_axes: &Vector3<f64>) -> Result<(), String> {
    let l = physical_limits(class);
    let mut e = [2.0 * semi_axes.x, 2.0 * semi_axes.y, 2.0 * semi_axes.z];
    e.sort_by(f64::total_cmp);
    let [small, middle, large] = e;
    let name = class.name();
    if !(small >= l.min) {
        return Err(format!("{small:.2} m across: no {name} is thinner than {} m", l.min));
    }
    if !(large <= l.max_length) {
        return Err(format!("{large:.2} m long: no {name} is longer than {} m", l.max_length));
    }
    if !(middle <= l.max_middle) {
        return Err(format!("{middle:.2} m wide or tall: no {name} exceeds {} m", l.max_middle));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_no_real_object_has_are_refused_and_real_ones_kept() {
        let v = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        // every class's prior size, and the prior's long axis 3σ off, is a real object
        for c in [0u16, 1, 2, 3, 5, 6, 7] {
            let p = class_prior(ClassId(c));
            assert!(physically_plausible(ClassId(c), &p.axes).is_ok(), "class {c} prior");
            let long = p.axes + Vector3::new(3.0 * p.sigma.x, 0.0, 0.0);
            assert!(physically_plausible(ClassId(c), &long).is_ok(), "class {c} prior + 3 sigma");
        }
        // the parked van of drive 0005 as fitted (semi-axes, m), and an articulated bus
        assert!(physically_plausible(ClassId(2), &v(2.11, 0.80, 0.73)).is_ok());
        assert!(physically_plausible(ClassId(5), &v(9.0, 1.6, 1.27)).is_ok());
        // the bus shelter of drive 0005 fitted as a truck: 12.6 m long, 1.2 m tall, 0.48 m wide
        let shelter = physically_plausible(ClassId(7), &v(6.3, 0.61, 0.24)).unwrap_err();
        assert!(shelter.contains("0.48 m across"), "{shelter}");
        // a 12 m car, a 25 m truck, a 3 m tall person, a 6 m wide bus
        assert!(physically_plausible(ClassId(2), &v(6.0, 0.8, 0.8)).unwrap_err().contains("12.00 m long"));
        assert!(physically_plausible(ClassId(7), &v(12.5, 1.5, 1.25)).is_err());
        assert!(physically_plausible(ClassId(0), &v(0.3, 1.5, 0.3)).is_err());
        assert!(physically_plausible(ClassId(5), &v(6.0, 3.0, 1.5)).unwrap_err().contains("6.00 m wide or tall"));
        // a degenerate fit (NaN axes) is not a real object either
        assert!(physically_plausible(ClassId(2), &v(f64::NAN, 0.8, 0.8)).is_err());
    }
}

//SUPER
