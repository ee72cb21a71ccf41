//! The JSON an app or a user hands the SDK: tracker and detector configs, a custom face model, a
//! body pose prior, an M3 configuration.
use monotrack_core::body::prior::PosePrior;
use monotrack_core::detect::DetectorConfig;
use monotrack_core::landmarks::M3Config;
use monotrack_core::model::FaceModel;
use monotrack_core::track::TrackerConfig;

/// One input of the `json_inputs` target.
pub fn run(data: &[u8]) {
    let Some((&which, json)) = data.split_first() else {
        return;
    };
    match which % 5 {
        0 => {
            if let Ok(c) = serde_json::from_slice::<TrackerConfig>(json) {
                let _ = c.validate();
            }
        }
        1 => {
            let _ = serde_json::from_slice::<DetectorConfig>(json);
        }
        2 => {
            let _ = FaceModel::from_json(json);
        }
        3 => {
            let _ = PosePrior::from_json(json);
        }
        _ => {
            let _ = M3Config::from_json(json);
        }
    }
}
