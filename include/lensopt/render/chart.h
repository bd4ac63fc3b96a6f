// A synthetic test chart, so `render` shows something meaningful without a dataset: a grid of
// thin lines, Siemens stars (36 spokes) at the centre and at 0.7 of the field on the diagonals,
// dark squares tilted by 5 degrees (slanted edges, for edge-spread measurements) on the
// horizontal and vertical axes, a column of colour patches (R, G, B, C, M, Y, white, grey), and
// text when a font is available. Values in [0, 1], RGB, antialiased by 4 x 4 supersampling.
#pragma once

#include <string>

#include "lensopt/render/image.h"

namespace lensopt {

struct ChartOptions {
  int width = 1280;
  int height = 720;
  bool text = true;  // try to draw labels (needs a font OpenImageIO can find)

  // Throws Error for sizes outside [32, 16384].
  void validate() const;
};

struct Chart {
  FloatImage image;
  bool text_drawn = false;
  std::string note;  // why text is missing, if it is
};

Chart make_test_chart(const ChartOptions& options);

}  // namespace lensopt
