// The text scanner the mesh readers share (mesh_io_{off,obj,ply,stl}.cc):
// line splitting with line numbers, whitespace tokens, number parsing that
// tells garbage from non-finite values, and the error messages that name the
// format and line. Internal to intake; no allocation beyond the caller's
// token vector.
//
//   LineReader reader(bytes);
//   std::string_view line;
//   std::vector<std::string_view> tokens;
//   while (reader.Next(&line)) SplitTokens(line, &tokens);
#ifndef TPR_EXTRACTOR_LIB_MESH_IO_TEXT_H_
#define TPR_EXTRACTOR_LIB_MESH_IO_TEXT_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "extractor/lib/intake.h"

namespace tpr::extract::mesh_io {

// LineReader splits bytes into lines ('\n', with a trailing '\r' removed)
// and numbers them from 1.
class LineReader {
 public:
  explicit LineReader(absl::string_view bytes) : bytes_(bytes) {}
  // Next sets *line to the next line and returns true, or returns false at
  // the end of the bytes.
  bool Next(absl::string_view* line);
  // number is the 1-based number of the last line returned.
  int64_t number() const { return number_; }
  // remaining is the count of bytes after the last line returned.
  size_t remaining() const {
    return pos_ >= bytes_.size() ? 0 : bytes_.size() - pos_;
  }

 private:
  absl::string_view bytes_;
  size_t pos_ = 0;
  int64_t number_ = 0;
};

// TokenCursor walks the whitespace-separated tokens of one line without
// storing them (a face line may hold millions of indices).
class TokenCursor {
 public:
  explicit TokenCursor(absl::string_view line) : line_(line) {}
  // Next sets *token to the next token and returns true, or returns false
  // when the line holds no more.
  bool Next(absl::string_view* token);

 private:
  absl::string_view line_;
  size_t pos_ = 0;
};

bool IsSpace(char c);

// HasBinaryBytes: control bytes other than whitespace never occur in a text
// mesh file; they mean binary data was handed to a text reader.
bool HasBinaryBytes(absl::string_view line);

// SplitTokens replaces *tokens with the whitespace-separated tokens of
// `line`, stopping after `max_tokens` of them.
void SplitTokens(absl::string_view line, std::vector<absl::string_view>* tokens,
                 size_t max_tokens = SIZE_MAX);

// StripComment returns `line` up to its first '#'.
absl::string_view StripComment(absl::string_view line);

// ParseDouble accepts what strtod accepts (one optional sign; "nan" and
// "inf" included, so that they can be reported as non-finite rather than as
// garbage); an overflow gives an infinity, an underflow 0 or a subnormal.
bool ParseDouble(absl::string_view token, double* value);

// ParseInt accepts one optional sign and decimal digits ("+-1" is refused,
// as strtol refuses it).
bool ParseInt(absl::string_view token, int64_t* value);

// Quote returns the token in single quotes, cut to 40 characters, with
// non-printable bytes as '?'.
std::string Quote(absl::string_view token);

absl::Status Invalid(absl::string_view format, absl::string_view message);
absl::Status InvalidAt(absl::string_view format, int64_t line,
                       absl::string_view message);
absl::Status TooManyVertices(int64_t n, const IntakeOptions& options);
absl::Status TooManyFaces(int64_t n, const IntakeOptions& options);

// CheckCoordinate checks a coordinate value already decoded (binary
// formats): finite and within kMaxCoordinate (intake.h). `where` names the
// element
// ("vertex 3", "triangle 2 corner 1").
absl::Status CheckCoordinateValue(absl::string_view format,
                                  absl::string_view where, double value);

// ParseCoordinate parses one coordinate token of vertex `vertex` on `line`
// into *value, rounded to float precision the way the readers always have
// (decimal to float, correctly rounded), so that a mesh gives the same
// signature as before the readers were rewritten. Errors: INVALID_ARGUMENT
// "<format> line L: vertex V: expected a coordinate, got 'x'", "... has a
// non-finite coordinate 'nan'", "... coordinate 'x' exceeds the supported
// magnitude 1e15".
absl::Status ParseCoordinate(absl::string_view format, int64_t line,
                             int64_t vertex, absl::string_view token,
                             double* value);

// LoadLe32 reads a little-endian 32-bit unsigned integer.
uint32_t LoadLe32(const char* p);

}  // namespace tpr::extract::mesh_io

#endif  // TPR_EXTRACTOR_LIB_MESH_IO_TEXT_H_
