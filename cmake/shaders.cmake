# previs_embed_shaders(TARGET SOURCES...): compiles each compute shader to SPIR-V with
# glslangValidator (one rule per shader, with a depfile so included headers are tracked) into
# a C header `<name>.spv.h` defining `uint32_t <name>_spv[]`, and adds the output folder to the
# target's include path. SPIR-V lives only in the build tree.
function(previs_embed_shaders target)
    set(out_dir ${CMAKE_CURRENT_BINARY_DIR}/spirv)
    file(MAKE_DIRECTORY ${out_dir})
    set(outputs)
    foreach(src ${ARGN})
        get_filename_component(name ${src} NAME_WE)
        set(out ${out_dir}/${name}.spv.h)
        add_custom_command(
            OUTPUT ${out}
            COMMAND ${GLSLANG_VALIDATOR} -V --target-env vulkan1.2 -g0
                    -I${CMAKE_SOURCE_DIR}
                    --depfile ${out_dir}/${name}.d --vn ${name}_spv
                    -o ${out} ${CMAKE_CURRENT_SOURCE_DIR}/${src}
            DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/${src}
            DEPFILE ${out_dir}/${name}.d
            COMMENT "glslang ${src}"
            VERBATIM)
        list(APPEND outputs ${out})
    endforeach()
    target_sources(${target} PRIVATE ${outputs})
    target_include_directories(${target} PRIVATE ${out_dir})
endfunction()
