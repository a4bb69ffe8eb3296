// The OpenCV calls of mousepose's calibration, as plain C functions for crates/opencv-calib/src/lib.rs.
//
// Every function returns 0 on success; on failure it returns 1 and copies the message of the
// exception it caught (cv::Exception or any std::exception) into the caller's buffer `err`
// of `err_len` bytes, NUL-terminated and cut to fit. No exception leaves this file.
//
// Images are 8-bit grey, row-major and tightly packed (width bytes a row); points are packed
// floats (x, y or x, y, z); matrices are row-major doubles. The Rust side checks every length
// before it calls.

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <exception>
#include <stdexcept>
#include <string>
#include <vector>

// The constants crates/opencv-calib/src/lib.rs passes by value.
static_assert(cv::CALIB_CB_ADAPTIVE_THRESH == 1, "CALIB_CB_ADAPTIVE_THRESH");
static_assert(cv::CALIB_CB_NORMALIZE_IMAGE == 2, "CALIB_CB_NORMALIZE_IMAGE");
static_assert(cv::CALIB_CB_FILTER_QUADS == 4, "CALIB_CB_FILTER_QUADS");
static_assert(cv::CALIB_CB_FAST_CHECK == 8, "CALIB_CB_FAST_CHECK");
static_assert(cv::CALIB_FIX_K3 == 128, "CALIB_FIX_K3");
static_assert(cv::SOLVEPNP_ITERATIVE == 0, "SOLVEPNP_ITERATIVE");
static_assert(cv::TermCriteria::COUNT == 1, "TermCriteria::COUNT");
static_assert(cv::TermCriteria::EPS == 2, "TermCriteria::EPS");

extern "C" {

// A caller's buffer of doubles: `capacity` values at `data`; the callee sets `len`.
struct OcbDoubles {
    double* data;
    size_t capacity;
    size_t len;
};

// A circle to draw: centre, radius, BGR colour and line thickness.
struct OcbCircle {
    int x;
    int y;
    int radius;
    double blue;
    double green;
    double red;
    int thickness;
};

// What a FileStorage node is, from its own checks.
struct OcbNodeInfo {
    int is_none;
    int empty;
    int is_map;
    int is_seq;
    int is_int;
    int is_real;
    int is_string;
    size_t size;
};

}  // extern "C"

struct OcbWriter {
    cv::FileStorage fs;
    std::string text;
};

struct OcbReader {
    std::string text;
    cv::FileStorage fs;
};

struct OcbNode {
    cv::FileNode node;
};

namespace {

void copy_message(const char* what, char* err, size_t err_len) noexcept {
    if (err == nullptr || err_len == 0) {
        return;
    }
    size_t n = what == nullptr ? 0 : std::strlen(what);
    if (n >= err_len) {
        n = err_len - 1;
    }
    if (n > 0) {
        std::memcpy(err, what, n);
    }
    err[n] = '\0';
}

// Runs `body`, turning any exception into status 1 and its message into `err`.
template <typename Body>
int guarded(char* err, size_t err_len, Body&& body) noexcept {
    try {
        body();
        return 0;
    } catch (const cv::Exception& e) {
        copy_message(e.what(), err, err_len);
    } catch (const std::exception& e) {
        copy_message(e.what(), err, err_len);
    } catch (...) {
        copy_message("an exception that is not a std::exception", err, err_len);
    }
    return 1;
}

// A Mat header over the caller's grey pixels (not copied; OpenCV only reads them).
cv::Mat grey_header(const unsigned char* pixels, int width, int height) {
    return cv::Mat(height, width, CV_8UC1, const_cast<unsigned char*>(pixels));
}

// A rows x cols matrix of doubles, copied from row-major `data`.
cv::Mat doubles(const double* data, int rows, int cols) {
    return cv::Mat(rows, cols, CV_64F, const_cast<double*>(data)).clone();
}

// Distortion coefficients as a 1 x len row, or none (an empty matrix) when len is 0.
cv::Mat coefficients(const double* data, size_t len) {
    return len == 0 ? cv::Mat() : doubles(data, 1, static_cast<int>(len));
}

std::vector<cv::Point2f> points2(const float* xy, size_t count) {
    std::vector<cv::Point2f> out(count);
    for (size_t i = 0; i < count; ++i) {
        out[i] = cv::Point2f(xy[2 * i], xy[2 * i + 1]);
    }
    return out;
}

std::vector<cv::Point3f> points3(const float* xyz, size_t count) {
    std::vector<cv::Point3f> out(count);
    for (size_t i = 0; i < count; ++i) {
        out[i] = cv::Point3f(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    }
    return out;
}

// A matrix's values as doubles, row-major (channels interleaved as OpenCV stores them).
std::vector<double> flatten(const cv::Mat& m) {
    std::vector<double> out;
    if (m.empty()) {
        return out;
    }
    cv::Mat d;
    m.convertTo(d, CV_64F);
    if (!d.isContinuous()) {
        d = d.clone();
    }
    const double* p = d.ptr<double>();
    out.assign(p, p + d.total() * static_cast<size_t>(d.channels()));
    return out;
}

void append(const std::vector<double>& values, OcbDoubles* out, const char* what) {
    if (out->len > out->capacity || values.size() > out->capacity - out->len) {
        throw std::length_error(std::string(what) + " has more values than expected");
    }
    std::copy(values.begin(), values.end(), out->data + out->len);
    out->len += values.size();
}

void put(const cv::Mat& m, OcbDoubles* out, const char* what) {
    out->len = 0;
    append(flatten(m), out, what);
}

// A 3-vector (rvec or tvec) into three doubles.
void put3(const cv::Mat& m, double* out, const char* what) {
    std::vector<double> v = flatten(m);
    if (v.size() != 3) {
        throw std::length_error(std::string(what) + " is not a 3-vector");
    }
    std::copy(v.begin(), v.end(), out);
}

cv::Mat vec3(const double* v) {
    return doubles(v, 3, 1);
}

cv::TermCriteria criteria(int type, int max_count, double epsilon) {
    return cv::TermCriteria(type, max_count, epsilon);
}

}  // namespace

extern "C" {

// cv::findChessboardCorners. Writes up to `capacity` corners (x, y) to `corners`, sets
// `count` to how many OpenCV gave and `found` to its verdict.
int ocb_find_chessboard_corners(const unsigned char* pixels, int width, int height, int cols, int rows,
                                int flags, float* corners, size_t capacity, size_t* count, int* found,
                                char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        std::vector<cv::Point2f> out;
        bool ok = cv::findChessboardCorners(grey_header(pixels, width, height), cv::Size(cols, rows), out,
                                            flags);
        *found = ok ? 1 : 0;
        *count = out.size();
        for (size_t i = 0; i < out.size() && i < capacity; ++i) {
            corners[2 * i] = out[i].x;
            corners[2 * i + 1] = out[i].y;
        }
    });
}

// cv::cornerSubPix on `count` corners (x, y), refined in place.
int ocb_corner_sub_pix(const unsigned char* pixels, int width, int height, float* corners, size_t count,
                       int win_width, int win_height, int zero_width, int zero_height, int term_type,
                       int max_count, double epsilon, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        std::vector<cv::Point2f> pts = points2(corners, count);
        cv::cornerSubPix(grey_header(pixels, width, height), pts, cv::Size(win_width, win_height),
                         cv::Size(zero_width, zero_height), criteria(term_type, max_count, epsilon));
        for (size_t i = 0; i < count; ++i) {
            corners[2 * i] = pts[i].x;
            corners[2 * i + 1] = pts[i].y;
        }
    });
}

// cv::calibrateCamera with standard deviations and per-view errors (calibrateCameraExtended):
// `views` views, view k of counts[k] points, packed one after another in `object` (x, y, z)
// and `image` (x, y).
int ocb_calibrate_camera(const float* object, const float* image, const size_t* counts, size_t views,
                         int width, int height, int flags, int term_type, int max_count, double epsilon,
                         OcbDoubles* camera_matrix, OcbDoubles* distortion, OcbDoubles* rvecs, OcbDoubles* tvecs,
                         OcbDoubles* std_intrinsics, OcbDoubles* std_extrinsics, OcbDoubles* per_view_errors,
                         double* rms, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        std::vector<std::vector<cv::Point3f>> object_points;
        std::vector<std::vector<cv::Point2f>> image_points;
        size_t at = 0;
        for (size_t k = 0; k < views; ++k) {
            object_points.push_back(points3(object + 3 * at, counts[k]));
            image_points.push_back(points2(image + 2 * at, counts[k]));
            at += counts[k];
        }
        cv::Mat k_out;
        cv::Mat d_out;
        std::vector<cv::Mat> r_out;
        std::vector<cv::Mat> t_out;
        cv::Mat std_in;
        cv::Mat std_ex;
        cv::Mat per_view;
        *rms = cv::calibrateCamera(object_points, image_points, cv::Size(width, height), k_out, d_out, r_out,
                                   t_out, std_in, std_ex, per_view, flags,
                                   criteria(term_type, max_count, epsilon));
        put(k_out, camera_matrix, "the camera matrix");
        put(d_out, distortion, "the distortion");
        rvecs->len = 0;
        for (const cv::Mat& r : r_out) {
            append(flatten(r), rvecs, "the rotations");
        }
        tvecs->len = 0;
        for (const cv::Mat& t : t_out) {
            append(flatten(t), tvecs, "the translations");
        }
        put(std_in, std_intrinsics, "the intrinsics' deviations");
        put(std_ex, std_extrinsics, "the extrinsics' deviations");
        put(per_view, per_view_errors, "the per-view errors");
    });
}

// cv::solvePnP of `count` points: the 3x3 camera matrix and `distortion_len` coefficients;
// `rvec`, `tvec` in (with a guess) and out, `solved` OpenCV's verdict.
int ocb_solve_pnp(const float* object, const float* image, size_t count, const double* camera_matrix,
                  const double* distortion, size_t distortion_len, int use_guess, int flags, double* rvec,
                  double* tvec, int* solved, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        std::vector<cv::Point3f> obj = points3(object, count);
        std::vector<cv::Point2f> img = points2(image, count);
        cv::Mat k = doubles(camera_matrix, 3, 3);
        cv::Mat d = coefficients(distortion, distortion_len);
        cv::Mat r;
        cv::Mat t;
        if (use_guess != 0) {
            r = vec3(rvec);
            t = vec3(tvec);
        }
        bool ok = cv::solvePnP(obj, img, k, d, r, t, use_guess != 0, flags);
        *solved = ok ? 1 : 0;
        if (ok) {
            put3(r, rvec, "solvePnP's rotation");
            put3(t, tvec, "solvePnP's translation");
        }
    });
}

// cv::solvePnPRefineLM from the pose in `rvec`, `tvec`, refined in place.
int ocb_solve_pnp_refine_lm(const float* object, const float* image, size_t count, const double* camera_matrix,
                            const double* distortion, size_t distortion_len, double* rvec, double* tvec,
                            int term_type, int max_count, double epsilon, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        std::vector<cv::Point3f> obj = points3(object, count);
        std::vector<cv::Point2f> img = points2(image, count);
        cv::Mat k = doubles(camera_matrix, 3, 3);
        cv::Mat d = coefficients(distortion, distortion_len);
        cv::Mat r = vec3(rvec);
        cv::Mat t = vec3(tvec);
        cv::solvePnPRefineLM(obj, img, k, d, r, t, criteria(term_type, max_count, epsilon));
        put3(r, rvec, "the refined rotation");
        put3(t, tvec, "the refined translation");
    });
}

// The grey image in colour (cv::cvtColor, COLOR_GRAY2BGR) with cv::drawFrameAxes of the pose
// (`rvec`, `tvec` as 3x1) and, when `circle` is not null, that circle (cv::circle, LINE_AA):
// the BGR pixels into `bgr`, which holds width * height * 3 bytes.
int ocb_draw_frame_axes(const unsigned char* pixels, int width, int height, const double* camera_matrix,
                        const double* distortion, size_t distortion_len, const double* rvec, const double* tvec,
                        float length, int thickness, const OcbCircle* circle, unsigned char* bgr,
                        size_t bgr_len, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        cv::Mat colour;
        cv::cvtColor(grey_header(pixels, width, height), colour, cv::COLOR_GRAY2BGR);
        cv::Mat k = doubles(camera_matrix, 3, 3);
        cv::Mat d = coefficients(distortion, distortion_len);
        cv::drawFrameAxes(colour, k, d, vec3(rvec), vec3(tvec), length, thickness);
        if (circle != nullptr) {
            cv::circle(colour, cv::Point(circle->x, circle->y), circle->radius,
                       cv::Scalar(circle->blue, circle->green, circle->red, 0.0), circle->thickness, cv::LINE_AA,
                       0);
        }
        if (colour.type() != CV_8UC3 || colour.cols != width || colour.rows != height) {
            throw std::logic_error("cvtColor gave an image of another size or type");
        }
        if (!colour.isContinuous()) {
            colour = colour.clone();
        }
        size_t n = colour.total() * 3;
        if (n != bgr_len) {
            throw std::length_error("the colour image does not fit its buffer");
        }
        std::memcpy(bgr, colour.ptr<unsigned char>(), n);
    });
}

// ---- FileStorage, in memory, YAML -------------------------------------------------------

int ocb_writer_new(OcbWriter** out, char* err, size_t err_len) {
    *out = nullptr;
    return guarded(err, err_len, [&] {
        auto* w = new OcbWriter();
        try {
            w->fs.open(".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML, "");
        } catch (...) {
            delete w;
            throw;
        }
        *out = w;
    });
}

void ocb_writer_free(OcbWriter* w) {
    try {
        delete w;
    } catch (...) {
    }
}

int ocb_writer_int(OcbWriter* w, const char* name, int value, char* err, size_t err_len) {
    return guarded(err, err_len, [&] { w->fs.write(name, value); });
}

int ocb_writer_real(OcbWriter* w, const char* name, double value, char* err, size_t err_len) {
    return guarded(err, err_len, [&] { w->fs.write(name, value); });
}

int ocb_writer_text(OcbWriter* w, const char* name, const char* value, char* err, size_t err_len) {
    return guarded(err, err_len, [&] { w->fs.write(name, std::string(value)); });
}

int ocb_writer_texts(OcbWriter* w, const char* name, const char* const* values, size_t count, char* err,
                     size_t err_len) {
    return guarded(err, err_len, [&] {
        std::vector<std::string> v(values, values + count);
        w->fs.write(name, v);
    });
}

// A rows x cols matrix of doubles from row-major `data` (an !!opencv-matrix).
int ocb_writer_matrix(OcbWriter* w, const char* name, int rows, int cols, const double* data, char* err,
                      size_t err_len) {
    return guarded(err, err_len, [&] { w->fs.write(name, doubles(data, rows, cols)); });
}

int ocb_writer_begin_map(OcbWriter* w, const char* name, char* err, size_t err_len) {
    return guarded(err, err_len, [&] { w->fs.startWriteStruct(name, cv::FileNode::MAP, ""); });
}

int ocb_writer_end_map(OcbWriter* w, char* err, size_t err_len) {
    return guarded(err, err_len, [&] { w->fs.endWriteStruct(); });
}

// Ends the document: its text stays in the writer (`text`, `len`) until it is freed.
int ocb_writer_finish(OcbWriter* w, const char** text, size_t* len, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        w->text = w->fs.releaseAndGetString();
        *text = w->text.data();
        *len = w->text.size();
    });
}

// Parses `text`; `opened` tells whether FileStorage holds a document.
int ocb_reader_open(const char* text, OcbReader** out, int* opened, char* err, size_t err_len) {
    *out = nullptr;
    return guarded(err, err_len, [&] {
        auto* r = new OcbReader();
        try {
            r->text = text;
            r->fs.open(r->text, cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML, "");
            *opened = r->fs.isOpened() ? 1 : 0;
        } catch (...) {
            delete r;
            throw;
        }
        *out = r;
    });
}

void ocb_reader_free(OcbReader* r) {
    try {
        delete r;
    } catch (...) {
    }
}

// The root's child `name` (FileStorage::operator[]).
int ocb_reader_get(const OcbReader* r, const char* name, OcbNode** out, char* err, size_t err_len) {
    *out = nullptr;
    return guarded(err, err_len, [&] { *out = new OcbNode{r->fs[std::string(name)]}; });
}

// A map's child `name` (FileNode::operator[] of a name).
int ocb_node_get(const OcbNode* n, const char* name, OcbNode** out, char* err, size_t err_len) {
    *out = nullptr;
    return guarded(err, err_len, [&] { *out = new OcbNode{n->node[std::string(name)]}; });
}

// A sequence's item `index` (FileNode::operator[] of an index).
int ocb_node_at(const OcbNode* n, int index, OcbNode** out, char* err, size_t err_len) {
    *out = nullptr;
    return guarded(err, err_len, [&] { *out = new OcbNode{n->node[index]}; });
}

void ocb_node_free(OcbNode* n) {
    try {
        delete n;
    } catch (...) {
    }
}

int ocb_node_info(const OcbNode* n, OcbNodeInfo* info, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        const cv::FileNode& f = n->node;
        info->is_none = f.isNone() ? 1 : 0;
        info->empty = f.empty() ? 1 : 0;
        info->is_map = f.isMap() ? 1 : 0;
        info->is_seq = f.isSeq() ? 1 : 0;
        info->is_int = f.isInt() ? 1 : 0;
        info->is_real = f.isReal() ? 1 : 0;
        info->is_string = f.isString() ? 1 : 0;
        info->size = f.size();
    });
}

int ocb_node_int(const OcbNode* n, int* out, char* err, size_t err_len) {
    return guarded(err, err_len, [&] { *out = static_cast<int>(n->node); });
}

int ocb_node_real(const OcbNode* n, double* out, char* err, size_t err_len) {
    return guarded(err, err_len, [&] { *out = static_cast<double>(n->node); });
}

// The node's text: its length into `len`, its bytes into `buf` when `capacity` holds them.
int ocb_node_string(const OcbNode* n, char* buf, size_t capacity, size_t* len, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        std::string s = static_cast<std::string>(n->node);
        *len = s.size();
        if (!s.empty() && s.size() <= capacity) {
            std::memcpy(buf, s.data(), s.size());
        }
    });
}

// The node read as a matrix (FileNode::mat). `matrix` is 0 when it is empty or has more than
// one channel; otherwise the matrix converted to doubles: its rows and cols, and its values
// row-major, their number into `len` and the values into `data` when `capacity` holds them.
int ocb_node_matrix(const OcbNode* n, int* matrix, int* rows, int* cols, double* data, size_t capacity,
                    size_t* len, char* err, size_t err_len) {
    return guarded(err, err_len, [&] {
        cv::Mat m = n->node.mat();
        *matrix = 0;
        *len = 0;
        if (m.empty() || m.channels() != 1) {
            return;
        }
        cv::Mat d;
        m.convertTo(d, CV_64F, 1.0, 0.0);
        *matrix = 1;
        *rows = d.rows;
        *cols = d.cols;
        std::vector<double> values;
        for (int r = 0; r < d.rows; ++r) {
            for (int c = 0; c < d.cols; ++c) {
                values.push_back(d.at<double>(r, c));
            }
        }
        *len = values.size();
        if (values.size() <= capacity) {
            std::copy(values.begin(), values.end(), data);
        }
    });
}

}  // extern "C"
