// fieldspace: the thin command line client of fieldspaced (see client/cli.h).

#include <iostream>
#include <string>
#include <vector>

#include "client/cli.h"

int main(int argc, char** argv) {
  std::vector<std::string> args(argv, argv + argc);
  return fieldspace::client::RunCli(args, std::cout, std::cerr);
}
