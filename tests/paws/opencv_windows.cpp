// OpenCV's own CascadeClassifier on grey images, for tests/paws.rs to compare ours with: its
// raw windows at scale 1 (minNeighbors 0, min and max size the window), one line "k x y" per
// window of the k-th image.
//
//   opencv_windows CASCADE.xml WIDTH HEIGHT IMAGE.pgm...
//
// Built by the test with the system's OpenCV (pkg-config opencv4), so that the crate's own
// build needs no bindings of objdetect (nor of dnn, which objdetect pulls in).
#include <opencv2/core.hpp>
#include <opencv2/core/ocl.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/objdetect.hpp>
#include <cstdio>
#include <cstdlib>
#include <vector>

int main(int argc, char **argv) {
    if (argc < 4) {
        std::fprintf(stderr, "usage: %s CASCADE.xml WIDTH HEIGHT IMAGE.pgm...\n", argv[0]);
        return 2;
    }
    cv::ocl::setUseOpenCL(false);
    cv::CascadeClassifier cascade(argv[1]);
    if (cascade.empty()) {
        std::fprintf(stderr, "OpenCV could not read the cascade %s\n", argv[1]);
        return 1;
    }
    const cv::Size window(std::atoi(argv[2]), std::atoi(argv[3]));
    for (int k = 4; k < argc; ++k) {
        const cv::Mat image = cv::imread(argv[k], cv::IMREAD_GRAYSCALE);
        if (image.empty()) {
            std::fprintf(stderr, "OpenCV could not read the image %s\n", argv[k]);
            return 1;
        }
        std::vector<cv::Rect> found;
        cascade.detectMultiScale(image, found, 1.1, 0, 0, window, window);
        for (const cv::Rect &r : found) {
            if (r.size() != window) {
                std::fprintf(stderr, "a window of %dx%d, not the cascade's\n", r.width, r.height);
                return 1;
            }
            std::printf("%d %d %d\n", k - 4, r.x, r.y);
        }
    }
    return 0;
}
