# Shared flags for servoamp's host C builds (included by amp_lib/Makefile
# and linux/telemetry/Makefile): the project's warning set and the
# sanitizer variant chosen with SAN=none|asan|tsan.
WARN := -std=c11 -Wall -Wextra -Werror -Wpedantic -Wshadow -Wstrict-prototypes
ifeq ($(SAN),asan)
SANFLAGS := -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
else ifeq ($(SAN),tsan)
SANFLAGS := -fsanitize=thread -fno-omit-frame-pointer
else
SANFLAGS :=
endif
