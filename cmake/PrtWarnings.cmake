# Warning flags for prtfarm's own targets; dependencies come in as -isystem and stay quiet.
add_library(prt_warnings INTERFACE)
target_compile_options(prt_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  $<$<BOOL:${PRT_WERROR}>:-Werror>)
add_library(prt_options INTERFACE)
if(PRT_SANITIZE)
  target_compile_options(prt_options INTERFACE -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  target_link_options(prt_options INTERFACE -fsanitize=address,undefined)
endif()

# prt_library(name LIBS ... [SOURCES ...] [EXCLUDE regex...]): one library per stage from every
# .cpp in the folder that is neither a test (*_test.cpp) nor an executable entry point
# (*_main.cpp), or from the SOURCES given (a folder that builds two libraries, docs/architecture.md).
function(prt_library name)
  cmake_parse_arguments(A "" "" "LIBS;EXCLUDE;SOURCES" ${ARGN})
  if(A_SOURCES)
    set(srcs ${A_SOURCES})
  else()
    prt_folder_sources(srcs ${CMAKE_CURRENT_SOURCE_DIR})
  endif()
  foreach(ex ${A_EXCLUDE})
    list(FILTER srcs EXCLUDE REGEX "${ex}")
  endforeach()
  if(NOT srcs)  # a stage whose first source has not been written yet
    add_library(${name} INTERFACE)
    target_include_directories(${name} INTERFACE ${CMAKE_SOURCE_DIR})
    target_link_libraries(${name} INTERFACE ${A_LIBS} prt_options)
    return()
  endif()
  add_library(${name} STATIC ${srcs})
  target_include_directories(${name} PUBLIC ${CMAKE_SOURCE_DIR})
  target_link_libraries(${name} PUBLIC ${A_LIBS} prt_options PRIVATE prt_warnings)
endfunction()

# prt_unit_tests(name LIBS ...): one GoogleTest executable from every *_test.cpp in the folder.
function(prt_unit_tests name)
  cmake_parse_arguments(A "" "" "LIBS" ${ARGN})
  if(NOT PRT_BUILD_TESTS)
    return()
  endif()
  file(GLOB srcs CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/*_test.cpp)
  if(NOT srcs)
    return()
  endif()
  add_executable(${name} ${srcs})
  target_link_libraries(${name} PRIVATE ${A_LIBS} GTest::gtest_main GTest::gmock prt_warnings)
  target_compile_definitions(${name} PRIVATE PRT_SOURCE_DIR="${CMAKE_SOURCE_DIR}"
                             PRT_DATA_DIR="${PRT_DATA_DIR}" PRT_SHARED_DATA_DIR="${PRT_SHARED_DATA_DIR}")
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT 600)
endfunction()
