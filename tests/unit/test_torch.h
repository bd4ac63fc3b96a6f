// libtorch's headers for the unit tests that build TorchScript modules (test_detector.cpp,
// test_joint_task.cpp), included before doctest: libtorch brings glog's CHECK macros, which must
// give way to doctest's. Once per translation unit, so that the two files compile together.
#pragma once

#ifdef LENSOPT_WITH_TORCH
#include <torch/script.h>
#include <torch/torch.h>
#undef CHECK
#undef CHECK_EQ
#undef CHECK_NE
#undef CHECK_LT
#undef CHECK_LE
#undef CHECK_GT
#undef CHECK_GE
#endif
