// Helpers for showing results with Apple types. The geometry itself (default intrinsics, upright
// size, projections, head axes, gaze arrows, the OpenGL transform) is the SDK's: `defaultCamera`,
// `uprightSize`, `projectPoint`, `headAxes`, `gazeArrows`, `openglTransform`, so that Swift keeps
// no copy that could drift from Kotlin's or the CLI's. Conventions (CONTRACT.md at the repository
// root): image pixels of the upright, mirrored-as-asked frame, x right, y down, origin at the
// top-left corner of the top-left pixel.
// CGPoint, CGSize and CGFloat come from CoreGraphics on Apple platforms, from Foundation elsewhere.
#if canImport(CoreGraphics)
import CoreGraphics
#endif
import Foundation
import MonotrackFFI

extension Point2 {
    /// The point as a `CGPoint`.
    public var cgPoint: CGPoint { CGPoint(x: CGFloat(x), y: CGFloat(y)) }
}

extension Face {
    /// The landmarks as `CGPoint`s.
    public var landmarkPoints: [CGPoint] { landmarks.map(\.cgPoint) }
}

extension Gestures {
    /// The most probable mouth gesture ("smile", "kiss", "neutral") and its probability.
    public var mouth: (name: String, probability: Float) {
        [("smile", smile), ("kiss", kiss), ("neutral", mouthNeutral)].max { $0.1 < $1.1 }!
    }

    /// The most probable brow gesture ("raise", "frown", "neutral") and its probability.
    public var brows: (name: String, probability: Float) {
        [("raise", browRaise), ("frown", browFrown), ("neutral", browNeutral)].max { $0.1 < $1.1 }!
    }
}

extension BenchReport {
    /// The per-stage table: stage, median ms, p90 ms.
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

    /// The mapping for a result's upright image (`frameWidth`×`frameHeight`) shown in `viewSize`.
    public init?(result: TrackingResult, viewSize: CGSize, fill: Bool) {
        self.init(imageSize: CGSize(width: CGFloat(result.frameWidth), height: CGFloat(result.frameHeight)),
                  viewSize: viewSize, fill: fill)
    }

    /// The view point of image point `p`.
    public func map(_ p: CGPoint) -> CGPoint { CGPoint(x: offset.x + scale * p.x, y: offset.y + scale * p.y) }

    /// The view point of an SDK image point (a landmark, a projection, an arrow's end).
    public func map(_ p: Point2) -> CGPoint { map(p.cgPoint) }
}
