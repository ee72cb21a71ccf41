// Benchmark app: runs the SDK's runBenchmark (the desktop bench's code) on bundled images and shows
// the per-stage table (stage, median ms, p90 ms).
plugins {
    alias(libs.plugins.android.application)
    alias(libs.plugins.kotlin.android)
}

android {
    namespace = "io.monotrack.bench"
    compileSdk = 35

    defaultConfig {
        applicationId = "io.monotrack.bench"
        minSdk = 24
        targetSdk = 35
        versionCode = 1
        versionName = "0.1.0"
    }

    buildTypes {
        release {
            // Benchmarks are only meaningful on release native code; R8 would not change them.
            isMinifyEnabled = false
            signingConfig = signingConfigs.getByName("debug")
        }
    }

    sourceSets {
        named("main") {
            // The repository's public-domain sample images (samples/data), bundled as they are.
            assets.srcDirs("../data")
        }
    }

    packaging {
        jniLibs { useLegacyPackaging = false }
    }

    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }
}

kotlin { jvmToolchain(17) }

dependencies {
    implementation(project(":monotrack"))
    implementation(libs.androidx.appcompat)
    implementation(libs.androidx.core.ktx)
}
