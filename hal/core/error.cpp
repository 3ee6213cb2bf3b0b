#include "hal/core/error.h"

#include <cstring>

namespace caphub {

std::string errnoText(int err) {
    if (err < 0) {
        err = -err;
    }
    char buf[128];
    // GNU strerror_r returns a pointer that may or may not be buf.
    const char* text = strerror_r(err, buf, sizeof buf);
    return text;
}

}  // namespace caphub
