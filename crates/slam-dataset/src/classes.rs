//! Object classes: COCO-80 indices, which the shipped detector uses, and the mapping of KITTI label
//! types onto them.

use slam_core::ClassId;

/// COCO "person".
pub const PERSON: ClassId = ClassId(0);
/// COCO "bicycle".
pub const BICYCLE: ClassId = ClassId(1);
/// COCO "car".
pub const CAR: ClassId = ClassId(2);
/// COCO "motorcycle".
pub const MOTORCYCLE: ClassId = ClassId(3);
/// COCO "bus".
pub const BUS: ClassId = ClassId(5);
/// COCO "train" (KITTI trams).
pub const TRAIN: ClassId = ClassId(6);
/// COCO "truck".
pub const TRUCK: ClassId = ClassId(7);

/// The class of a KITTI label type: Car and Van → car, Truck → truck, Tram → train, Pedestrian and
/// Person (sitting) → person, Cyclist → bicycle. `Misc` and `DontCare` have no class (`None`).
pub fn kitti_class(kind: &str) -> Option<ClassId> {
    match kind {
        "Car" | "Van" => Some(CAR),
        "Truck" => Some(TRUCK),
        "Tram" => Some(TRAIN),
        "Pedestrian" | "Person" | "Person_sitting" => Some(PERSON),
        "Cyclist" => Some(BICYCLE),
        _ => None,
    }
}

/// Name of a class id: its COCO name (`slam_core::ClassId::name`), for tables and overlays.
pub fn name(class: ClassId) -> &'static str {
    class.name()
}
