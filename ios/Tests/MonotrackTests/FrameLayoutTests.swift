#if canImport(ImageIO)
import CoreGraphics
import ImageIO
#endif
import Foundation
import XCTest
@testable import Monotrack

final class FrameLayoutTests: XCTestCase {
    func testNV12PassesTheLumaPlaneAsGray8WithItsStride() throws {
        let choice = try FrameLayout.choice(for: PixelFormatCode.nv12Full)
        XCTAssertEqual(choice.format, .gray8)
        XCTAssertTrue(choice.planar)
        let orientation = try FrameOrientation(rotationDegrees: 90, mirrored: true)
        let (desc, count) = try FrameLayout.describe(
            choice, width: 1920, height: 1080, bytesPerRow: 1984, orientation: orientation)
        XCTAssertEqual(desc.format, .gray8)
        XCTAssertEqual(desc.rowStride, 1984)
        XCTAssertEqual(desc.rotationDegrees, 90)
        XCTAssertTrue(desc.mirrored)
        XCTAssertEqual(count, 1984 * 1079 + 1920)
    }

    func testBGRAIsPackedFourBytesPerPixel() throws {
        let choice = try FrameLayout.choice(for: PixelFormatCode.bgra)
        let (desc, count) = try FrameLayout.describe(choice, width: 640, height: 480, bytesPerRow: 2560, orientation: .up)
        XCTAssertEqual(desc.format, .bgra8)
        XCTAssertEqual(count, 2560 * 480)
        // Strides and sizes are the SDK's to check, with its error.
        assertInvalidFrame(try FrameLayout.describe(choice, width: 640, height: 480, bytesPerRow: 2559, orientation: .up))
        assertInvalidFrame(try FrameLayout.describe(choice, width: 0, height: 480, bytesPerRow: 2560, orientation: .up))
        XCTAssertThrowsError(try FrameLayout.describe(choice, width: -1, height: 480, bytesPerRow: 2560, orientation: .up)) {
            guard case .invalidLayout? = $0 as? FrameError else { return XCTFail("\($0)") }
        }
    }

    func testUnsupportedFormatNamesItsFourCC() {
        XCTAssertThrowsError(try FrameLayout.choice(for: 0x7934_3230)) { error in // 'y420'
            XCTAssertEqual(error as? FrameError, .unsupportedPixelFormat(0x7934_3230))
            XCTAssertTrue("\(error)".contains("'y420'"))
        }
    }

    #if canImport(ImageIO)
    func testExifOrientationsMapToRotateThenMirror() {
        let expected: [(CGImagePropertyOrientation, UInt32, Bool)] = [
            (.up, 0, false), (.upMirrored, 0, true), (.down, 180, false), (.downMirrored, 180, true),
            (.right, 90, false), (.rightMirrored, 270, true), (.left, 270, false), (.leftMirrored, 90, true),
        ]
        for (exif, degrees, mirrored) in expected {
            let o = FrameOrientation(exif)
            XCTAssertEqual(o.rotationDegrees, degrees, "\(exif)")
            XCTAssertEqual(o.mirrored, mirrored, "\(exif)")
        }
    }
    #endif

    func testRotationAnglesNormaliseAndRejectNonQuarterTurns() throws {
        XCTAssertEqual(try FrameOrientation(videoRotationAngle: 90, frontCamera: true).rotationDegrees, 90)
        XCTAssertEqual(try FrameOrientation(rotationDegrees: -90, mirrored: false).rotationDegrees, 270)
        XCTAssertEqual(try FrameOrientation(rotationDegrees: 450, mirrored: false).rotationDegrees, 90)
        XCTAssertThrowsError(try FrameOrientation(rotationDegrees: 45, mirrored: false))
        XCTAssertThrowsError(try FrameOrientation(rotationDegrees: .nan, mirrored: false))
        XCTAssertThrowsError(try FrameOrientation(rotationDegrees: 9e18, mirrored: false))
        let turned = try FrameOrientation(rotationDegrees: -90, mirrored: false)
        let (desc, _) = try FrameLayout.describe(try FrameLayout.choice(for: PixelFormatCode.gray), width: 640, height: 480,
                                                 bytesPerRow: 640, orientation: turned)
        XCTAssertEqual(try uprightSize(desc: desc), FrameSize(width: 480, height: 640))
    }
}

/// The SDK's overlay rules as Swift sees them, and the wrapper's view helpers.
final class ResultHelperTests: XCTestCase {
    private let identity: [Double] = [1, 0, 0, 0, 1, 0, 0, 0, 1]

    func testDefaultCameraFollowsTheContract() throws {
        let k = try defaultCamera(width: 640, height: 480)
        XCTAssertEqual(k.fx, 576, accuracy: 1e-9)
        XCTAssertEqual(k.fy, 576, accuracy: 1e-9)
        XCTAssertEqual(k.cx, 320, accuracy: 1e-9)
        XCTAssertEqual(k.cy, 240, accuracy: 1e-9)
        assertInvalidConfig(try defaultCamera(width: 0, height: 480))
    }

    func testFrontalPoseAxesProjectAlongImageAxes() throws {
        let k = CameraIntrinsics(fx: 500, fy: 500, cx: 320, cy: 240)
        let pose = HeadPose(rotation: identity, translationMm: Vec3(x: 10, y: -20, z: 500), yawDeg: 0, pitchDeg: 0, rollDeg: 0)
        let a = try XCTUnwrap(try headAxes(pose: pose, camera: k, lengthMm: 50))
        XCTAssertEqual(a.origin.x, 330, accuracy: 1e-4)
        XCTAssertEqual(a.x.x, 380, accuracy: 1e-4)
        XCTAssertEqual(a.y.y, 270, accuracy: 1e-4)
        XCTAssertEqual(a.z, projectPoint(camera: k, pointMm: Vec3(x: 10, y: -20, z: 550)), "z points away from the camera")
        let behind = HeadPose(rotation: identity, translationMm: Vec3(x: 0, y: 0, z: -500), yawDeg: 0, pitchDeg: 0, rollDeg: 0)
        XCTAssertNil(try headAxes(pose: behind, camera: k, lengthMm: 50))
        let bad = HeadPose(rotation: [1, 0], translationMm: Vec3(x: 0, y: 0, z: 500), yawDeg: 0, pitchDeg: 0, rollDeg: 0)
        assertInvalidConfig(try headAxes(pose: bad, camera: k, lengthMm: 50))
        XCTAssertEqual(projectPoint(camera: k, pointMm: Vec3(x: 10, y: 0, z: 100)), Point2(x: 370, y: 240))
        XCTAssertNil(projectPoint(camera: k, pointMm: Vec3(x: 10, y: 0, z: 0)))
    }

    func testGazeArrowsStartAtTheEyeCentroids() throws {
        var points = [Point2](repeating: Point2(x: 0, y: 0), count: 68)
        for i in 36..<42 { points[i] = Point2(x: 100 + Float(i - 36), y: 50) }
        for i in 42..<48 { points[i] = Point2(x: 200, y: 60 + Float(i - 42)) }
        let gaze = Gaze(left: Vec3(x: 0, y: 1, z: 0), right: Vec3(x: 0.5, y: -0.5, z: -0.7), combined: Vec3(x: 0, y: 0, z: -1))
        let a = try gazeArrows(landmarks: points, gaze: gaze, lengthPx: 20)
        XCTAssertEqual(a.right, Arrow(from: Point2(x: 102.5, y: 50), to: Point2(x: 112.5, y: 40)))
        XCTAssertEqual(a.left, Arrow(from: Point2(x: 200, y: 62.5), to: Point2(x: 200, y: 82.5)))
    }

    func testViewMappingFillsAndFits() throws {
        let fill = try XCTUnwrap(ViewMapping(imageSize: CGSize(width: 480, height: 640), viewSize: CGSize(width: 360, height: 640), fill: true))
        XCTAssertEqual(fill.scale, 1, accuracy: 1e-9)
        XCTAssertEqual(fill.offset.x, -60, accuracy: 1e-9)
        XCTAssertEqual(fill.map(Point2(x: 60, y: 10)), CGPoint(x: 0, y: 10))
        let fit = try XCTUnwrap(ViewMapping(imageSize: CGSize(width: 480, height: 640), viewSize: CGSize(width: 360, height: 640), fill: false))
        XCTAssertEqual(fit.scale, 0.75, accuracy: 1e-9)
        XCTAssertEqual(fit.offset.y, 80, accuracy: 1e-9)
        XCTAssertNil(ViewMapping(imageSize: .zero, viewSize: CGSize(width: 1, height: 1), fill: true))
    }

    func testBenchTableIsInMilliseconds() {
        let r = BenchReport(device: "t", iterations: 3, faces: 1, modelLoadUs: 0,
                            stages: [StageStat(name: "landmarks", medianUs: 1234, p90Us: 2000, meanUs: 1300)])
        let lines = r.table.split(separator: "\n")
        XCTAssertEqual(lines.count, 2)
        XCTAssertEqual(lines[1].split(separator: " ").map(String.init), ["landmarks", "1.23", "2.00"])
    }
}
