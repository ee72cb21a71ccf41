// Point of gaze through the generated Swift (the port of bindings/tests/kotlin/GazeTest.kt):
// targets from JSON and a phone screen, each face's point of gaze, a tap calibration, typed errors.
import Foundation
import XCTest
@testable import Monotrack

final class GazeTests: XCTestCase {
    /// The sample face as upright, tightly packed 8-bit luma.
    private func face() throws -> (bytes: Data, desc: FrameDesc) {
        let img = try sample()
        return grayFrame(reference(img, rot: 0, mirrored: false).pixels, width: img.width, height: img.height)
    }

    func testTheDriverZonesParseAndBadTargetsAreTypedErrors() throws {
        let zones = try gazeTargetsFromJson(json: repoFile("examples/driver_zones.json"))
        XCTAssertEqual(zones.map(\.id),
                       ["left_window", "left_mirror", "road", "navigation", "rear_mirror", "right_mirror", "right_window"])
        assertInvalidConfig(try gazeTargetsFromJson(json: #"{"targets": []}"#))
        assertInvalidConfig(try screenTarget(id: "s", widthMm: -1, heightMm: 100, cameraRightMm: 0, cameraDownMm: 0))
        let t = try FaceTracker(options: options(.video))
        let line = GazeTarget(id: "line", cornersMm: [Vec3(x: 0, y: 0, z: 0), Vec3(x: 1, y: 0, z: 0), Vec3(x: 2, y: 0, z: 0)])
        assertInvalidConfig(try t.setGazeTargets(targets: [line]))
        let phone = try screenTarget(id: "phone", widthMm: 70, heightMm: 150, cameraRightMm: 35, cameraDownMm: -8)
        assertInvalidConfig(try t.setGazeTargets(targets: [phone, phone]), "a repeated id")
    }

    func testFacesCarryAPointOfGazeAndATapCalibratesIt() throws {
        let (buf, desc) = try face()
        let t = try FaceTracker(options: options(.video))
        try t.setGazeTargets(targets: [screenTarget(id: "phone", widthMm: 70, heightMm: 150, cameraRightMm: 35, cameraDownMm: -8)])
        let firstFaces = try t.detectForVideo(bytes: buf, desc: desc, timestampMs: 10).faces
        XCTAssertEqual(firstFaces.count, 1)
        let first = try XCTUnwrap(firstFaces.first?.pointOfGaze)
        XCTAssertTrue((200...3000).contains(first.originMm.z), "origin \(first.originMm)")
        XCTAssertEqual(first.target?.nearest, "phone")
        assertInvalidFrame(try t.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 10, vMm: 10), timestampMs: 5000),
                           "no face near the tap's time")
        assertInvalidConfig(try t.addCalibrationPoint(targetId: "tv", point: PlanePoint(uMm: 10, vMm: 10), timestampMs: 11),
                            "an unknown target")
        XCTAssertEqual(try t.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 20, vMm: 90), timestampMs: 11), 1,
                       "a video tracker counts the taps")
        let hit = try XCTUnwrap(t.detectForVideo(bytes: buf, desc: desc, timestampMs: 43).faces.first?.pointOfGaze?.target)
        XCTAssertTrue(hit.hit && hypot(hit.point.uMm - 20, hit.point.vMm - 90) < 10, "landed at \(hit.point)")
        t.resetGazeCalibration()
        try t.setGazeTargets(targets: [])
        let none = try XCTUnwrap(t.detectForVideo(bytes: buf, desc: desc, timestampMs: 76).faces.first?.pointOfGaze)
        XCTAssertNil(none.target)
    }
}
