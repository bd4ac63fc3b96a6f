// TaskOptions (the tasks are in torch/, loaded by torch_loader.cpp).
#include "lensopt/joint/task.h"

#include <fmt/format.h>

#include <cmath>

#include "lensopt/core/error.h"

namespace lensopt {

void TaskOptions::validate() const {
  if (!(learning_rate >= 0.0) || !std::isfinite(learning_rate))
    throw Error(fmt::format("task learning rate {} must be finite and >= 0", learning_rate));
  if (channels < 1 || channels > 4)
    throw Error(fmt::format("task channels = {} must be 1 to 4", channels));
  if (features < 1 || features > 1024)
    throw Error(fmt::format("task features = {} must be 1 to 1024", features));
  if (layers < 2 || layers > 64)
    throw Error(fmt::format("task layers = {} must be 2 to 64", layers));
  if (threads < 1 || threads > 256)
    throw Error(fmt::format("task threads = {} must be 1 to 256", threads));
}

}  // namespace lensopt
