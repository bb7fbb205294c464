// The gnuplot writer of `slimrt bench`: see bench_plot.h.
#include "bench_plot.h"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <vector>

#include "slimrt/error.h"
#include "slimrt/output.h"

namespace slim::bench {

namespace {

// Creates an empty file for gnuplot's messages in the system's temporary folder ($TMPDIR or
// /tmp) and returns its name; its name holds no quote, so that it can be quoted for the shell.
std::string gnuplot_log() {
  std::error_code ec;
  std::string dir = std::filesystem::temp_directory_path(ec).string();
  if (ec || dir.find('\'') != std::string::npos) dir = "/tmp";
  std::string name = dir + "/slimrt-gnuplot-XXXXXX";
  const int fd = ::mkstemp(name.data());
  if (fd < 0)
    throw Error("cannot create a file for gnuplot's messages in '" + dir +
                "': " + std::strerror(errno));
  ::close(fd);
  return name;
}

// Runs gnuplot on `script` (whose "set output" names SLIM_PLOT_OUTPUT) through write_atomically:
// the PNG appears complete or not at all. gnuplot's own error lines are kept for the message.
bool run_gnuplot(const std::string& script, const std::string& png_path, std::string* why) {
  try {
    write_atomically(png_path, [&](const std::string& tmp) {
      std::string quoted = "'";
      for (char c : tmp) quoted += c == '\'' ? std::string("''") : std::string(1, c);
      quoted += "'";
      std::string full = script;
      const std::string marker = "SLIM_PLOT_OUTPUT";
      if (const size_t at = full.find(marker); at != std::string::npos)
        full.replace(at, marker.size(), quoted);
      // gnuplot's messages go to a file of their own in the system's temporary folder, not
      // beside the output: the output may be a device or a pipe (/dev/stdout, a FIFO), whose
      // folder takes no new file.
      const std::string log = gnuplot_log();
      FILE* pipe = popen(("gnuplot 2> '" + log + "'").c_str(), "w");
      if (!pipe) {
        const int e = errno;
        std::remove(log.c_str());
        throw Error("could not start gnuplot: " + std::string(std::strerror(e)));
      }
      std::fwrite(full.data(), 1, full.size(), pipe);
      const int status = pclose(pipe);
      std::string said;
      if (FILE* f = std::fopen(log.c_str(), "r")) {
        char line[512];
        while (std::fgets(line, sizeof line, f)) {
          std::string l(line);
          while (!l.empty() && (l.back() == '\n' || l.back() == ' ')) l.pop_back();
          if (!l.empty()) said = l;  // the last non-empty line holds gnuplot's error
        }
        std::fclose(f);
      }
      std::remove(log.c_str());
      if (status != 0) {
        std::string what =
            status == -1 ? std::string("could not wait for gnuplot")
            : WIFEXITED(status)
                ? "gnuplot exited with code " + std::to_string(WEXITSTATUS(status)) + ", expected 0"
            : WIFSIGNALED(status)
                ? "gnuplot was killed by signal " + std::to_string(WTERMSIG(status))
                : "gnuplot failed";
        throw Error(what + (said.empty() ? std::string() : ": " + said));
      }
    });
  } catch (const Error& e) {
    if (why) *why = e.what();
    return false;
  }
  return true;
}

}  // namespace

bool write_plot(const BenchReport& report, const std::string& png_path, std::string* why) {
  auto fail = [&](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (std::system("gnuplot --version > /dev/null 2>&1") != 0)
    return fail("gnuplot not found (Debian package gnuplot-nox; scripts/setup.sh installs it)");

  // One panel per scene with at least one point.
  std::vector<std::string> scenes;
  for (const BenchRow& r : report.rows)
    if (r.bytes_per_triangle && r.mrays_diffuse && *r.bytes_per_triangle > 0 &&
        std::find(scenes.begin(), scenes.end(), r.scene) == scenes.end())
      scenes.push_back(r.scene);
  if (scenes.empty()) return fail("no configuration has both bytes/triangle and diffuse MRays/s");

  auto quote = [](const std::string& s) {  // gnuplot single-quoted string
    std::string out = "'";
    for (char c : s) out += c == '\'' ? std::string("''") : std::string(1, c);
    return out + "'";
  };
  std::ostringstream g;
  const int panel_h = 520;
  g << "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {\n"
    << "  set terminal pngcairo size 960," << panel_h * int(scenes.size()) << " font ',10'\n"
    << "} else {\n"
    << "  set terminal png size 960," << panel_h * int(scenes.size()) << "\n"
    << "}\n"
    << "set output SLIM_PLOT_OUTPUT\n"
    << "set multiplot layout " << scenes.size() << ",1\n"
    << "set logscale x\nset grid\nset key top right\n"
    << "set xlabel 'memory: bytes per input triangle (log scale)'\n"
    << "set ylabel 'diffuse MRays/s (workload 2)'\n"
    << "set offsets graph 0.05, graph 0.25, graph 0.1, graph 0.05\n";
  for (size_t s = 0; s < scenes.size(); ++s) {
    std::ostringstream emb, sli;
    for (const BenchRow& r : report.rows) {
      if (r.scene != scenes[s] || !r.bytes_per_triangle || !r.mrays_diffuse ||
          *r.bytes_per_triangle <= 0)
        continue;
      (r.embree ? emb : sli) << "\"" << r.config << "\" " << *r.bytes_per_triangle << " "
                             << r.mrays_diffuse->median << "\n";
    }
    std::vector<std::string> parts;
    auto block = [&](const std::string& data, const char* tag, const char* colour,
                     const char* title) {
      if (data.empty()) return;
      const std::string name = std::string("$").append(tag).append(std::to_string(s));
      g << name << " << EOD\n" << data << "EOD\n";
      parts.push_back(name + " using 2:3 with points pt 7 ps 1.3 lc rgb '" + colour + "' title '" +
                      title + "'");
      parts.push_back(name + " using 2:3:1 with labels left offset char 0.8,0.4 font ',8' notitle");
    };
    block(emb.str(), "embree", "#c0392b", "Embree 3");
    block(sli.str(), "slim", "#1f5fbf", "slimrt");
    g << "set title "
      << quote(scenes[s] + ": " + std::to_string(report.machine.threads) + " threads, " +
               report.machine.cpu)
      << "\nplot ";
    for (size_t i = 0; i < parts.size(); ++i) g << (i ? ", \\\n     " : "") << parts[i];
    g << "\n";
  }
  g << "unset multiplot\n";

  return run_gnuplot(g.str(), png_path, why);
}

}  // namespace slim::bench
