// chart_table.cpp: CSV writing, gnuplot rendering and shared helpers of `kiln chart`.
#include "tools/chart/chart_table.h"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "src/text_file.h"

namespace kiln::chart {
namespace {

std::string csvCell(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

// Single-quoted for gnuplot (a quote inside is doubled).
std::string gnuplotQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') out += '\'';
    out += c;
  }
  return out + "'";
}

}  // namespace

int ChartTable::column(const std::string& n) const {
  for (size_t i = 0; i < columns.size(); ++i)
    if (columns[i] == n) return int(i);
  return -1;
}

std::string num(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::string chartCsv(const ChartTable& t) {
  std::ostringstream s;
  for (const std::string& n : t.notes) s << "# " << n << "\n";
  for (size_t i = 0; i < t.columns.size(); ++i) s << (i ? "," : "") << csvCell(t.columns[i]);
  s << "\n";
  for (const auto& row : t.rows) {
    for (size_t i = 0; i < row.size(); ++i) s << (i ? "," : "") << csvCell(row[i]);
    s << "\n";
  }
  return s.str();
}

Status writeChartCsv(const std::string& dir, const ChartTable& t) {
  return writeTextFileAtomically(dir + "/" + t.name + ".csv", chartCsv(t));
}

std::string findGnuplot() {
  const char* path = std::getenv("PATH");
  if (!path) return "";
  std::stringstream dirs(path);
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    if (dir.empty()) continue;
    const std::string candidate = dir + "/gnuplot";
    if (::access(candidate.c_str(), X_OK) == 0) return candidate;
  }
  return "";
}

Status renderChartPng(const std::string& gnuplot, const std::string& dir, const ChartTable& t,
                      int width, int height) {
  const std::string csv = dir + "/" + t.name + ".csv";
  const std::string png = dir + "/" + t.name + ".png";
  const std::string pngTmp = png + ".tmp";
  const std::string script = dir + "/" + t.name + ".gp.tmp";
  const std::string log = dir + "/" + t.name + ".gnuplot.log.tmp";
  std::string body = t.plot;
  for (size_t at; (at = body.find("@CSV@")) != std::string::npos;)
    body.replace(at, 5, gnuplotQuote(csv));
  std::ostringstream s;
  s << "set terminal pngcairo size " << width << "," << height
    << " enhanced font 'Sans,10'\n"
    << "set output " << gnuplotQuote(pngTmp) << "\n"
    << "set datafile separator ','\n"
    << "set datafile columnheaders\n"
    << "set title " << gnuplotQuote(t.title) << " noenhanced\n"
    << "set grid\n"
    << "set key noenhanced\n"
    << body << "\n"
    << "unset output\n";
  if (Status st = writeTextFileAtomically(script, s.str()); !st) return st;
  // Run gnuplot without a shell (paths may hold anything), stdout and stderr to the log.
  const pid_t pid = ::fork();
  if (pid < 0) {
    std::remove(script.c_str());
    return Error{"gnuplot: cannot start a process"};
  }
  if (pid == 0) {
    std::FILE* f = std::freopen(log.c_str(), "w", stdout);
    if (f) ::dup2(::fileno(stdout), 2);
    ::execl(gnuplot.c_str(), gnuplot.c_str(), script.c_str(), static_cast<char*>(nullptr));
    std::_Exit(127);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  std::string messages;
  {
    std::ifstream in(log);
    std::stringstream ss;
    ss << in.rdbuf();
    messages = ss.str();
  }
  std::remove(script.c_str());
  std::remove(log.c_str());
  const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  std::error_code ec;
  if (!ok || !std::filesystem::exists(pngTmp, ec) || std::filesystem::file_size(pngTmp, ec) == 0) {
    std::remove(pngTmp.c_str());
    while (!messages.empty() && messages.back() == '\n') messages.pop_back();
    return Error{png + ": gnuplot failed" + (messages.empty() ? "" : ": " + messages)};
  }
  std::filesystem::rename(pngTmp, png, ec);
  if (ec) {
    std::remove(pngTmp.c_str());
    return Error{png + ": " + ec.message()};
  }
  return Status::success();
}

std::string machineDescription() {
  std::string model;
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      const size_t colon = line.find(':');
      if (colon != std::string::npos) model = line.substr(colon + 2);
      break;
    }
  }
  std::string out = std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
  if (!model.empty()) out += " (" + model + ")";
  return out;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double quantile(std::vector<double> v, double f) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = std::clamp(f, 0.0, 1.0) * double(v.size() - 1);
  const size_t i = size_t(pos);
  const double t = pos - double(i);
  return i + 1 < v.size() ? v[i] * (1.0 - t) + v[i + 1] * t : v[i];
}

double logLogSlope(const std::vector<double>& x, const std::vector<double>& y) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (size_t i = 0; i < std::min(x.size(), y.size()); ++i) {
    if (!(x[i] > 0.0) || !(y[i] > 0.0)) continue;
    const double lx = std::log(x[i]), ly = std::log(y[i]);
    sx += lx;
    sy += ly;
    sxx += lx * lx;
    sxy += lx * ly;
    ++n;
  }
  if (n < 2) return 0.0;
  const double d = n * sxx - sx * sx;
  return d != 0.0 ? (n * sxy - sx * sy) / d : 0.0;
}

}  // namespace kiln::chart
