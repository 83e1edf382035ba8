//! The mapper's bookkeeping: the objects by track, the tracks merged into another object, counters.

use std::collections::BTreeMap;

use slam_assoc::ObjectTracker;
use slam_core::{Associator, TrackId};
use slam_optim::SharedOptimizer;

use super::{method::FitMethod, MappedObject, MapperConfig};

/// The object mapper.
pub struct ObjectMapper {
    pub(super) tracker: ObjectTracker,
    pub(super) config: MapperConfig,
    pub(super) objects: BTreeMap<TrackId, MappedObject>,
    /// Tracks found to duplicate another object; their detections are ignored.
    pub(super) merged: BTreeMap<TrackId, TrackId>,
    pub(super) fits: usize,
    pub(super) implausible: usize,
    pub(super) free_space_removed: usize,
    pub(super) optimizer: SharedOptimizer,
    pub(super) method: FitMethod,
    /// Objects of a loaded map ([`ObjectMapper::restore`]): each re-enters association as a track
    /// when its ellipsoid projects into the view and no live track holds it.
    pub(super) loaded: std::collections::BTreeSet<TrackId>,
}

impl ObjectMapper {
    /// A mapper around an associator; object fits use `optimizer`.
    pub fn new(associator: Box<dyn Associator>, config: MapperConfig, optimizer: SharedOptimizer) -> Self {
        Self {
            tracker: ObjectTracker::new(associator, config.tracker),
            config,
            objects: BTreeMap::new(),
            merged: BTreeMap::new(),
            fits: 0,
            implausible: 0,
            free_space_removed: 0,
            optimizer,
            method: FitMethod::default(),
            loaded: Default::default(),
        }
    }

    /// Use `method` for the ellipsoid fits (default: [`FitMethod::default`], Tri+Yaw+refine).
    pub fn with_method(mut self, method: FitMethod) -> Self {
        self.method = method;
        self
    }

    /// The fitting method.
    pub fn method(&self) -> &FitMethod {
        &self.method
    }

    /// All objects, by id.
    pub fn objects(&self) -> impl Iterator<Item = &MappedObject> {
        self.objects.values()
    }

    /// One object.
    pub fn object(&self, id: TrackId) -> Option<&MappedObject> {
        self.objects.get(&id)
    }

    /// Number of ellipsoid fits run so far.
    pub fn fits(&self) -> usize {
        self.fits
    }

    /// Fitted ellipsoids refused because no real object of the class has their size
    /// ([`physically_plausible`]).
    pub fn implausible_fits(&self) -> usize {
        self.implausible
    }

    /// Ellipsoids removed because the stereo points saw free space through them
    /// ([`ObjectMapper::check_free_space`]).
    pub fn free_space_removals(&self) -> usize {
        self.free_space_removed
    }

    /// Objects of the same class group whose ellipsoid centres are closer than `merge_distance_m` are one
    /// object seen as two tracks (a detector that boxes a car twice, a track broken by a missed
    /// detection): the one with fewer observations is dropped and its later detections ignored.
    pub(super) fn merge_duplicates(&mut self, id: TrackId) {
        let Some(c) = self.objects.get(&id).and_then(|o| o.ellipsoid.map(|e| (e.centre(), o.class))) else { return };
        let other = self.objects.values().find(|o| {
            o.id != id
                && o.class.group() == c.1.group()
                && !o.moving
                && o.ellipsoid.is_some_and(|e| (e.centre() - c.0).norm() < self.config.merge_distance_m)
        });
        let Some(other) = other.map(|o| o.id) else { return };
        let n = |k: &TrackId| self.objects.get(k).map_or(0, |o| o.observations.len());
        // keep the longer track (the older one on a tie)
        let (keep, drop) = if (n(&other), std::cmp::Reverse(other)) >= (n(&id), std::cmp::Reverse(id)) {
            (other, id)
        } else {
            (id, other)
        };
        if let Some(gone) = self.objects.remove(&drop) {
            tracing::debug!(kept = %keep, dropped = %drop, "duplicate object merged");
            if let Some(k) = self.objects.get_mut(&keep) {
                k.points.extend(gone.points);
                for (f, p) in gone.surface {
                    k.surface.entry(f).or_insert(p);
                }
            }
            self.merged.insert(drop, keep);
        }
    }

    /// Tracks merged into another object (dropped → kept).
    pub fn merged(&self) -> &BTreeMap<TrackId, TrackId> {
        &self.merged
    }
}
