import Monotrack
import SwiftUI

/// Draws a result over the aspect-fill preview: landmarks, head axes (x red, y green, z blue), gaze
/// arrows, the most probable mouth and brow gestures, the eyes' openness, and the frame rate. The
/// geometry is the SDK's (`headAxes`, `gazeArrows` through the result's own `camera`); this view
/// only maps it to the screen.
struct OverlayView: View {
    let result: TrackingResult?
    let fps: Double

    /// Axis length: about half a face width, so the gizmo stays inside the head.
    private static let axisLengthMm = 70.0
    /// Gaze arrow length in result-image pixels: visible at 640x480 without covering the face.
    private static let gazeArrowPx: Float = 60

    var body: some View {
        Canvas { context, size in
            guard let result else { return }
            let ms = Double(result.timings.totalUs) / 1000
            context.draw(Text(String(format: "%.1f fps  %.1f ms", fps, ms)).font(.headline).foregroundColor(.white),
                         at: CGPoint(x: 16, y: 60), anchor: .topLeading)
            guard let m = ViewMapping(result: result, viewSize: size, fill: true) else { return }

            for face in result.faces {
                for p in face.landmarks {
                    let v = m.map(p)
                    context.fill(Path(ellipseIn: CGRect(x: v.x - 2, y: v.y - 2, width: 4, height: 4)), with: .color(.cyan))
                }
                // Both calls fail only on malformed input, which a tracker's own result never is.
                if let a = try? headAxes(pose: face.pose, camera: result.camera, lengthMm: Self.axisLengthMm) {
                    for (tip, color) in [(a.x, Color.red), (a.y, .green), (a.z, .blue)] {
                        context.stroke(line(m.map(a.origin), m.map(tip)), with: .color(color), lineWidth: 3)
                    }
                }
                if let gaze = face.gaze,
                   let g = try? gazeArrows(landmarks: face.landmarks, gaze: gaze, lengthPx: Self.gazeArrowPx) {
                    for arrow in [g.right, g.left] {
                        context.stroke(line(m.map(arrow.from), m.map(arrow.to)), with: .color(.yellow), lineWidth: 2)
                    }
                }
                var label = String(format: "yaw %.0f°", face.pose.yawDeg)
                if let g = face.gestures {
                    let mouth = g.mouth, brows = g.brows
                    label = String(format: "%@ %.2f  brows %@ %.2f  ", mouth.name, mouth.probability,
                                   brows.name, brows.probability) + label
                }
                if let eyes = face.eyes {
                    // The subject's own eyes, 1 open: which side of the image each is on depends on mirroring.
                    label += String(format: "  eyes L %.2f R %.2f", eyes.leftOpen, eyes.rightOpen)
                }
                let corner = m.map(CGPoint(x: CGFloat(face.bbox.x), y: CGFloat(face.bbox.y)))
                context.draw(Text(label).font(.caption).foregroundColor(.white), at: corner, anchor: .bottomLeading)
            }
        }
        .allowsHitTesting(false)
    }

    private func line(_ a: CGPoint, _ b: CGPoint) -> Path {
        var p = Path()
        p.move(to: a)
        p.addLine(to: b)
        return p
    }
}
