import Monotrack
import SwiftUI

struct ContentView: View {
    @StateObject private var camera = CameraModel()

    var body: some View {
        ZStack {
            CameraPreview(session: camera.session, rotationAngle: camera.previewRotationAngle)
            OverlayView(result: camera.result, fps: camera.fps)
            if let message = camera.message {
                Text(message).padding().background(.thinMaterial, in: RoundedRectangle(cornerRadius: 8))
            }
        }
        .ignoresSafeArea()
        .task { await camera.start() }
        .onDisappear { camera.stop() }
    }
}
