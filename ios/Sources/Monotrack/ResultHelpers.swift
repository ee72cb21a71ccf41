// Helpers for drawing results. Conventions (CONTRACT.md at the repository root): image pixels of the upright,
// mirrored-as-asked frame, x right, y down, origin at the top-left corner of the top-left pixel;
// camera frame x right, y down, z forward, millimetres; the pose maps model X to R·X + t.
// CGPoint, CGSize and CGFloat come from CoreGraphics on Apple platforms, from Foundation elsewhere.
#if canImport(CoreGraphics)
import CoreGraphics
#endif
import Foundation
import MonotrackFFI

/// Number of landmarks in a `Face` (the 68-point iBUG / 300-W order).
public let landmarkCount = 68

/// Focal length in units of the larger image side when intrinsics are unknown (CONTRACT: ≈58° FOV).
public let defaultFocalPerMaxSide = 0.9

/// iBUG indices of the subject's right eye (image left for a frontal face).
public let rightEyeIndices = 36...41
/// iBUG indices of the subject's left eye (image right for a frontal face).
public let leftEyeIndices = 42...47

/// The intrinsics the SDK assumes when none are given: f = 0.9 · max(width, height), centred.
public func defaultIntrinsics(width: Int, height: Int) -> CameraIntrinsics {
    let f = defaultFocalPerMaxSide * Double(max(width, height))
    return CameraIntrinsics(fx: f, fy: f, cx: Double(width) / 2, cy: Double(height) / 2)
}

extension CameraIntrinsics {
    /// Projects a camera-frame point (mm) to pixels; nil on or behind the camera plane.
    public func project(x: Double, y: Double, z: Double) -> CGPoint? {
        guard z > 0 else { return nil }
        return CGPoint(x: fx * x / z + cx, y: fy * y / z + cy)
    }
}

/// The head's model axes in the image: x towards the subject's left, y down, z away from the camera.
public struct HeadAxes: Equatable {
    /// The model origin (the pose's translation), projected.
    public let origin: CGPoint
    /// Tip of the model x axis (towards the subject's left).
    public let x: CGPoint
    /// Tip of the model y axis (down the face).
    public let y: CGPoint
    /// Tip of the model z axis (into the head, away from the camera).
    public let z: CGPoint
}

extension HeadPose {
    /// The rotation as a row-major 3×3 array, or nil when it is not 9 finite values.
    public var rotationMatrix: [Double]? {
        rotation.count == 9 && rotation.allSatisfy(\.isFinite) ? rotation : nil
    }

    /// Projects the model axes, `lengthMm` long, for a pose gizmo.
    ///
    /// - Parameter camera: intrinsics of the upright result image (`defaultIntrinsics` with the
    ///   result's `frameWidth`/`frameHeight` when the tracker has no `camera`).
    /// - Returns: nil when the rotation is malformed or an endpoint is behind the camera.
    public func axes(camera: CameraIntrinsics, lengthMm: Double) -> HeadAxes? {
        guard let r = rotationMatrix else { return nil }
        let t = translationMm
        // Column j of R is model axis j in the camera frame.
        func tip(_ j: Int) -> CGPoint? {
            camera.project(x: t.x + lengthMm * r[j], y: t.y + lengthMm * r[3 + j], z: t.z + lengthMm * r[6 + j])
        }
        guard let o = camera.project(x: t.x, y: t.y, z: t.z), let x = tip(0), let y = tip(1), let z = tip(2)
        else { return nil }
        return HeadAxes(origin: o, x: x, y: y, z: z)
    }
}

extension Face {
    /// The landmarks as `CGPoint`s.
    public var landmarkPoints: [CGPoint] { landmarks.map { CGPoint(x: CGFloat($0.x), y: CGFloat($0.y)) } }

    /// Gaze arrows (from, to) for the subject's right and left eye: from each eye's landmark centroid
    /// along the gaze direction's image-plane part, `lengthPx` long for a gaze across the optical
    /// axis (an orthographic sketch for overlays). Nil without 68 landmarks or without gaze
    /// (`TrackerConfig.gaze` off, or the ultra-light mode).
    public func gazeArrows(lengthPx: CGFloat) -> (right: (CGPoint, CGPoint), left: (CGPoint, CGPoint))? {
        guard landmarks.count == landmarkCount, let gaze = gaze else { return nil }
        func centroid(_ r: ClosedRange<Int>) -> CGPoint {
            let pts = landmarks[r]
            let n = CGFloat(pts.count)
            return CGPoint(x: pts.reduce(0) { $0 + CGFloat($1.x) } / n, y: pts.reduce(0) { $0 + CGFloat($1.y) } / n)
        }
        func arrow(_ eye: CGPoint, _ g: Vec3) -> (CGPoint, CGPoint) {
            (eye, CGPoint(x: eye.x + lengthPx * CGFloat(g.x), y: eye.y + lengthPx * CGFloat(g.y)))
        }
        return (arrow(centroid(rightEyeIndices), gaze.right), arrow(centroid(leftEyeIndices), gaze.left))
    }
}

extension Gestures {
    /// The most probable mouth gesture ("smile", "frown", "kiss", "neutral") and its probability.
    public var mouth: (name: String, probability: Float) {
        [("smile", smile), ("frown", frown), ("kiss", kiss), ("neutral", mouthNeutral)].max { $0.1 < $1.1 }!
    }

    /// The most probable brow gesture ("raise", "frown", "neutral") and its probability.
    public var brows: (name: String, probability: Float) {
        [("raise", browRaise), ("frown", browFrown), ("neutral", browNeutral)].max { $0.1 < $1.1 }!
    }
}

extension BenchReport {
    /// The per-stage table like the thesis' Tables 4.4/4.5: stage, median ms, p90 ms.
    public var table: String {
        let w = max(5, stages.map(\.name.count).max() ?? 0)
        func pad(_ s: String, _ n: Int) -> String { s.padding(toLength: max(n, s.count), withPad: " ", startingAt: 0) }
        func num(_ us: Double) -> String {
            let s = String(format: "%.2f", us / 1000)
            return String(repeating: " ", count: max(0, 10 - s.count)) + s
        }
        var out = pad("stage", w) + "  median ms     p90 ms\n"
        for s in stages {
            out += pad(s.name, w) + " " + num(s.medianUs) + " " + num(s.p90Us) + "\n"
        }
        return out
    }
}

/// Maps result-image points to view points for an image shown aspect-fill (the default
/// `AVCaptureVideoPreviewLayer.videoGravity = .resizeAspectFill`) or aspect-fit, centred.
public struct ViewMapping: Equatable {
    /// View points per image pixel.
    public let scale: CGFloat
    /// View position of the image origin.
    public let offset: CGPoint

    /// The mapping for `imageSize` shown in `viewSize`; nil when a size is empty.
    public init?(imageSize: CGSize, viewSize: CGSize, fill: Bool) {
        guard imageSize.width > 0, imageSize.height > 0, viewSize.width > 0, viewSize.height > 0 else { return nil }
        let sx = viewSize.width / imageSize.width
        let sy = viewSize.height / imageSize.height
        scale = fill ? max(sx, sy) : min(sx, sy)
        offset = CGPoint(x: (viewSize.width - scale * imageSize.width) / 2,
                         y: (viewSize.height - scale * imageSize.height) / 2)
    }

    /// The view point of image point `p`.
    public func map(_ p: CGPoint) -> CGPoint { CGPoint(x: offset.x + scale * p.x, y: offset.y + scale * p.y) }
}
