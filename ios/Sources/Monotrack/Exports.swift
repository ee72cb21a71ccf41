// Apps import `Monotrack` alone: the generated API (`FaceTracker`, `FaceTrackerOptions`, the records
// and the frame and overlay rules) is re-exported, so there is one name for each type and the
// wrappers here only add Apple types on top of it.
@_exported import MonotrackFFI
