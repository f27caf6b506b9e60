// SPDX-License-Identifier: MIT OR Apache-2.0
//
// Flamenco 3 custom job type: runs `logsh render` over chunks of a frame range, one task
// per chunk. Copy this file into the `scripts/` directory next to `flamenco-manager`
// and restart the Manager; the job type appears as "logsh Render". Workers run it as a
// `misc` task, so any Worker with `logsh` on its PATH (or at `logsh_exe`) can take it.
//
// Each task resumes with --skip-existing: a task that is re-queued after a Worker died
// finishes the frames the first attempt left, and leaves the finished ones untouched.

const JOB_TYPE = {
    label: "logsh Render",
    description: "Shade a scene directory (format v1) with log-SH visibility into multi-layer EXRs.",
    settings: [
        {
            key: "scene_dir",
            type: "string",
            subtype: "dir_path",
            required: true,
            description: "Scene directory holding scene.json, as the Workers see it",
        },
        {
            key: "frames",
            type: "string",
            required: true,
            default: "1-24",
            description: "Frames to render: '47', '1-240', '1-240x2', '1,5,10-20'",
        },
        {
            key: "chunk_size",
            type: "int32",
            default: 10,
            description: "Frames per task",
        },
        {
            key: "render_output",
            type: "string",
            subtype: "dir_path",
            required: true,
            description: "Output directory (receives render.NNNN.exr and render.NNNN.png)",
        },
        {
            key: "quality",
            type: "string",
            choices: ["draft", "default", "high", "ultra"],
            default: "default",
            description: "logsh --quality preset",
        },
        {
            key: "extra_args",
            type: "string",
            default: "",
            description: "More logsh render flags, separated by spaces (e.g. '--order 6 --colour-type float')",
            visible: "submission",
        },
        {
            key: "logsh_exe",
            type: "string",
            default: "logsh",
            description: "The logsh executable on the Workers",
            visible: "submission",
        },
    ],
};

function compileJob(job) {
    const settings = job.settings;
    const extra = settings.extra_args.split(" ").filter((a) => a.length > 0);
    const chunks = frameChunker(settings.frames, settings.chunk_size);
    for (const chunk of chunks) {
        const task = author.Task(`logsh-${chunk}`, "misc");
        task.addCommand(
            author.Command("exec", {
                exe: settings.logsh_exe,
                args: [
                    "render",
                    settings.scene_dir,
                    "--frames", chunk,
                    "--out", settings.render_output,
                    "--quality", settings.quality,
                    "--skip-existing",
                    "--progress", "lines",
                    ...extra,
                ],
            })
        );
        job.addTask(task);
    }
}
