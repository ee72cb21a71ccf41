import Monotrack
import SwiftUI

struct ContentView: View {
    @StateObject private var camera = CameraModel()

    var body: some View {
        ZStack {
            CameraPreview(session: camera.session, rotationAngle: camera.previewRotationAngle)
            OverlayView(result: camera.result, fps: camera.fps)
            VStack {
                HStack {
                    Spacer()
                    // The model starts and stops the recording off the main thread; the switch
                    // follows what it reports.
                    Toggle("Record", isOn: Binding(get: { camera.isRecording }, set: { camera.setRecording($0) }))
                        .fixedSize()
                        .padding(8)
                        .background(.thinMaterial, in: RoundedRectangle(cornerRadius: 8))
                }
                Spacer()
            }
            .padding()
            if let message = camera.message {
                Text(message).padding().background(.thinMaterial, in: RoundedRectangle(cornerRadius: 8))
            }
        }
        .ignoresSafeArea()
        .task { await camera.start() }
        .onDisappear { camera.stop() }
    }
}
